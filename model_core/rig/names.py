"""Names a whole skeleton shares (no bpy): a character's prefix on every bone (MotionBuilder's ``Character1_Hips``,
OptiTrack Motive's ``Skeleton_Hip``) or a pipeline's suffix (Maya's ``Hips_jnt``), which the bone map and the BVH
reader read past where the names as they are leave joints open (:func:`bare_names`)."""

from __future__ import annotations

from collections import Counter

# A prefix every bone of a skeleton carries (MotionBuilder's ``Character1_Hips``, OptiTrack Motive's ``Skeleton_Hip``,
# a character's name in a game export) ends in one of these, a suffix (Maya's ``_jnt``, ``_JNT``, ``_bind``) starts
# with one; all but at most this share of the bones carry it (a root or a reference bone added later may not).
_AFFIX_EDGES = "_:|.- "
_UNPREFIXED_SHARE = 0.1
_PREFIX_MIN_BONES = 8


def _shared(names: list[str], cuts) -> str:
    """The longest of the affixes ``cuts(name)`` yields (each with something left beside it) that all but
    :data:`_UNPREFIXED_SHARE` of ``names`` carry, or ``""`` (also under :data:`_PREFIX_MIN_BONES` names). Counted in
    one pass: an MMD model or a VRoid avatar has hundreds of bones."""
    if len(names) < _PREFIX_MIN_BONES:
        return ""
    need = len(names) - int(_UNPREFIXED_SHARE * len(names))
    counts = Counter(affix for name in names for affix in set(cuts(name)))
    return max((a for a, k in counts.items() if k >= need), key=len, default="")


def shared_prefix(names: list[str]) -> str:
    """The longest prefix ending in a separator that all (but at most :data:`_UNPREFIXED_SHARE`) of ``names`` start
    with, leaving something after it in each: ``"Character1_"`` of MotionBuilder's ``Character1_Hips``,
    ``Character1_LeftUpLeg``, ...; ``""`` where there is none (or under :data:`_PREFIX_MIN_BONES` names)."""
    return _shared(names, lambda name: (name[:end] for end in range(1, len(name)) if name[end - 1] in _AFFIX_EDGES))


def shared_suffix(names: list[str]) -> str:
    """:func:`shared_prefix` at the other end: the longest suffix starting with a separator (Maya's ``_jnt`` of
    ``Hips_jnt``, ``thigh_l_jnt``, ...)."""
    return _shared(names, lambda name: (name[start:] for start in range(1, len(name)) if name[start] in _AFFIX_EDGES))


def bare_names(names: list[str]) -> list[str]:
    """``names`` without the prefix and the suffix they share (:func:`shared_prefix`, :func:`shared_suffix`), where
    a bone carries them; ``names`` as they are where they share neither. A BVH End Site's name (its joint's with
    ``_end``) is read as its joint's."""
    given = set(names)
    end = [n.endswith("_end") and n[:-4] in given for n in names]
    own = [n for n, e in zip(names, end) if not e]
    prefix, suffix = shared_prefix(own), shared_suffix(own)

    def bare(n):
        n = n[len(prefix):] if prefix and n.startswith(prefix) else n
        return n[:-len(suffix)] if suffix and n.endswith(suffix) and len(n) > len(suffix) else n

    return [bare(n[:-4]) + "_end" if e else bare(n) for n, e in zip(names, end)]
