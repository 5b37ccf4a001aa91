"""Forward kinematics of a Blender-style armature and the positions-to-rotations solve.

Everything here is in ARMATURE space (the armature object's local frame, any axes,
any unit): the Blender side converts world and model positions in and out.

Glossary
--------
- Rig: bones in parent-first order; ``rest`` ``[B, 4, 4]`` is each bone's rest matrix
  in armature space (Blender's ``Bone.matrix_local``: head at the translation, the
  bone along its local +Y).
- Pose (Blender's "basis"): per bone a local location ``[F, B, 3]`` and rotation
  ``[F, B, 3, 3]`` relative to the rest pose, so that
  ``pose[b] = pose[parent] @ inv(rest[parent]) @ rest[b] @ T(loc) @ R(rot)``.
- Anchor: where a canonical joint sits on the rig: bone ``index`` and whether it is
  the bone's head (``tail=False``) or tail; or, for a torso joint the rig has no bone for
  (:data:`PLACED`: one spine bone, no neck bone), a share of the way between the mapped
  torso joints below and above it.

The solve keeps the rig's bone lengths: only the root bone (the one mapped to the
hips, or where that is connected to its parent the bone above that carries it) moves;
every other mapped bone is rotated so that it points at its canonical children.
A bone with several canonical children (hips, chest) takes the rotation that
best fits all of them (body planes: hips and shoulders, by a Kabsch fit); a bone with
one child swings from its reference pose by the shortest arc, and upper legs and upper
arms then twist about their own axis so the knee and elbow planes follow the targets.
Bones with no canonical child and bones outside the map keep their reference pose.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..motion.conventions import JOINT_INDEX, JOINTS, PARENT_NAMES
from ..motion.geometry import nearest_rotation, rotvec_to_matrix, shortest_arc, unit

# Upper limbs whose twist follows the plane of (joint, child, grandchild).
_PLANE_TWIST = {"l_upleg": ("l_knee", "l_foot"), "r_upleg": ("r_knee", "r_foot"),
                "l_arm": ("l_elbow", "l_wrist"), "r_arm": ("r_elbow", "r_wrist")}
# Plane normals shorter than this (sine of the bend angle) give no twist; full twist above _TWIST_FULL.
_TWIST_NONE, _TWIST_FULL = 0.05, 0.25
_REACH_GIVE = 2.0  # a knee or elbow moves at most this many times as far as its limb's end would miss
_IN_LINE = 1e-3  # the sine (and, for a head at the joint, the share of the way) under which a bone is in line
CHILDREN = {j: tuple(c for c in JOINTS if PARENT_NAMES[c] == j) for j in JOINTS}

# Torso joints a rig may have no bone for: a chest where the rig has one spine bone, a neck where its head sits
# on its chest. Such a joint is placed on the line between the mapped torso joints below and above it, at the
# share of the way that the body the model learnt gives it (its bones' lengths from the spine up, metres: the
# release's seed windows, :func:`features.learnt_body`), and the bone below it turns to carry what it carries.
PLACED = ("spine1", "neck")
_TORSO = ("spine", "spine1", "neck", "head")
_TORSO_LENGTHS = {"spine1": 0.098, "neck": 0.178, "head": 0.070}


def placed_between(present) -> dict[str, tuple[str, str, float]]:
    """{joint: (torso joint below, torso joint above, share of the way from below)} for each joint of
    :data:`PLACED` not in ``present`` (the mapped joints' names)."""
    out = {}
    for joint in PLACED:
        if joint in present:
            continue
        k = _TORSO.index(joint)
        below = next(t for t in reversed(_TORSO[:k]) if t in present or t not in PLACED)
        above = next(t for t in _TORSO[k + 1:] if t in present or t not in PLACED)
        span = lambda a, b: sum(_TORSO_LENGTHS[t] for t in _TORSO[_TORSO.index(a) + 1:_TORSO.index(b) + 1])
        out[joint] = (below, above, span(below, joint) / span(below, above))
    return out


def placed(mapping: dict[str, tuple[str, bool]]) -> dict[str, tuple[str, str, float]]:
    """:func:`placed_between` for the joints a bone map ``mapping`` (joint -> (bone, use tail)) has no bone for."""
    return placed_between({j for j in JOINTS if mapping.get(j) and mapping[j][0]})


class SolveError(ValueError):
    """A bone map does not fit the rig's hierarchy."""


@dataclass
class Rig:
    """An armature's rest pose. ``parents`` int ``[B]`` (-1 for roots, parents first),
    ``rest`` ``[B, 4, 4]`` armature space, ``lengths`` ``[B]`` in armature units.

    Each rest matrix's rotation is taken as the rotation nearest to it: Blender's ``Bone.matrix_local`` of a bone
    that points straight up or down (a leg, an MMD model's lower body) is a rotation only to about 1e-4, and a chain
    of bones that turns each child from its parent's turn would grow that by a factor of about three a bone."""

    names: list[str]
    parents: np.ndarray
    rest: np.ndarray
    lengths: np.ndarray
    connected: np.ndarray | None = None  # bool [B]: heads on their parent's tail (Blender's ``use_connect``)
    # [B, 3]: where a joint at each bone's tail sits, in the bone's rest frame; None: the tail, ``lengths`` along
    # its Y axis (:func:`tips_along_the_limb` moves a hand's that points across it)
    tails: np.ndarray | None = None

    def __post_init__(self):
        self.parents = np.asarray(self.parents, dtype=np.int64)
        self.connected = (np.zeros(len(self.parents), bool) if self.connected is None
                          else np.asarray(self.connected, bool) & (self.parents >= 0))
        self.rest = np.array(self.rest, dtype=np.float64)
        self.rest[:, :3, :3] = nearest_rotation(self.rest[:, :3, :3])
        self.lengths = np.asarray(self.lengths, dtype=np.float64)
        if self.tails is None:
            self.tails = np.zeros((len(self.lengths), 3))
            self.tails[:, 1] = self.lengths
        self.tails = np.asarray(self.tails, dtype=np.float64)
        for b, p in enumerate(self.parents):
            if p >= b:
                raise SolveError(f"bone {self.names[b]!r} comes before its parent; order bones parents first")
        inv_parent = np.linalg.inv(self.rest[np.maximum(self.parents, 0)])
        rel = inv_parent @ self.rest
        self.rel_rest = np.where((self.parents < 0)[:, None, None], self.rest, rel)  # (B, 4, 4)

    def index(self, name: str) -> int:
        return self.names.index(name)

    def is_ancestor(self, a: int, b: int) -> bool:
        """Whether bone ``a`` is ``b`` or one of its ancestors."""
        while b >= 0:
            if a == b:
                return True
            b = int(self.parents[b])
        return False


@dataclass
class Anchors:
    """Where each canonical joint sits: ``bone`` int ``[21]`` and ``tail`` bool ``[21]``; ``between``: the joints
    placed between two others (:data:`PLACED`), {joint index: (index below, index above, share)}, whose ``bone``
    is the one of the joint below them (the bone that carries them)."""

    bone: np.ndarray
    tail: np.ndarray
    between: dict[int, tuple[int, int, float]] = field(default_factory=dict)

    @classmethod
    def from_map(cls, rig: Rig, mapping: dict[str, tuple[str, bool]]) -> Anchors:
        """``mapping``: canonical joint -> (bone name, use tail); a joint of :data:`PLACED` it leaves out is placed
        between its neighbours (:func:`placed_between`). Raises :class:`SolveError`."""
        named = placed(mapping)
        missing = [j for j in JOINTS if j not in named and (not mapping.get(j) or mapping[j][0] not in rig.names)]
        if missing:
            raise SolveError(f"no bone mapped for: {', '.join(missing)}")
        between = {JOINT_INDEX[j]: (JOINT_INDEX[a], JOINT_INDEX[b], share) for j, (a, b, share) in named.items()}
        bone = np.array([rig.index(mapping[named[j][0] if j in named else j][0]) for j in JOINTS])
        tail = np.array([j not in named and bool(mapping[j][1]) for j in JOINTS])
        out = cls(bone, tail, between)
        out.check(rig)
        return out

    def carrier(self, j: int) -> int:
        """The joint whose bone carries joint ``j``: itself, or for a placed joint the mapped one below it."""
        return self.between[j][0] if j in self.between else j

    def check(self, rig: Rig) -> None:
        """Each canonical child must sit below its parent joint's bone, at a distinct place (a placed joint's
        neighbours: the one above below the one below)."""
        for j, name in enumerate(JOINTS):
            parent = PARENT_NAMES[name]
            if parent is None:  # the hips: at a bone's head, or at its tail (an MMD model's lower body)
                continue
            if j in self.between:
                continue
            p = self.carrier(JOINT_INDEX[parent])
            same = self.bone[j] == self.bone[p] and self.tail[j] == self.tail[p]
            on_tail = self.tail[p] and PARENT_NAMES[JOINTS[p]] is not None  # the hips may be a tail (an MMD model's)
            if same or not rig.is_ancestor(int(self.bone[p]), int(self.bone[j])) or on_tail:
                raise SolveError(f"joint {name} (bone {rig.names[self.bone[j]]!r}) must be a different place "
                                 f"below joint {JOINTS[p]} (bone {rig.names[self.bone[p]]!r})")

    def on_bones(self) -> dict[int, str]:
        """{bone: canonical joint} of the joints at bone heads, and the hips wherever they are (the bones the solve
        aims)."""
        return {int(self.bone[j]): name for j, name in enumerate(JOINTS)
                if (not self.tail[j] or PARENT_NAMES[name] is None) and j not in self.between}


# Hand length (wrist to middle finger tip) as a fraction of the forearm's.
HAND_TO_FOREARM = 0.73
# A hand's tail more than this far off the line of its forearm is no finger tip: an FBX from Maya or Unreal imported
# without Automatic Bone Orientation can point a bone's tail across it, and Blender's BVH importer stands a bone that
# ends in a zero-length End Site (a Bandai take's hands) straight up.
ACROSS_DEG = 60.0


def points_across(along: np.ndarray, way: np.ndarray, limit_deg: float = ACROSS_DEG) -> bool:
    """Whether a bone's tail direction ``along`` ``[3]`` is more than ``limit_deg`` off the limb's line ``way`` ``[3]``
    (False where either has no length)."""
    norms = float(np.linalg.norm(along) * np.linalg.norm(way))
    return norms > 1e-12 and float(np.dot(along, way)) < np.cos(np.radians(limit_deg)) * norms


# The ball of the foot from the ankle, in shin lengths: forward the way the body faces, and down (the standard
# skeleton's, ``motion.synthetic``: 0.14 and 0.05 m from a 0.43 m shin).
FOOT_FORWARD, FOOT_DROP = 0.33, 0.12


def facing_and_up(at: dict[str, np.ndarray]):
    """(the way a body faces, the way up its spine made square to that), unit ``[3]`` each, from canonical joints at
    rest ``{joint: [3]}``: across the body from right to left (the mean of the thighs', knees' and ankles' each side
    has; a rig whose thighs both start at the middle of its hips has its knees apart), crossed with up from the hips to
    the head. Blender's -Y for a character made facing the front view (+Z in the model's axes); None where the map
    gives neither line or they lie along each other."""
    legs = [k for k in ("upleg", "knee", "foot") if f"l_{k}" in at and f"r_{k}" in at]
    if not legs or "hips" not in at or "head" not in at:
        return None
    across = np.mean([at[f"l_{k}"] - at[f"r_{k}"] for k in legs], axis=0)
    up = at["head"] - at["hips"]
    forward = np.cross(across, up)
    size = float(np.linalg.norm(forward))
    if size < 1e-6 * max(float(np.linalg.norm(across) * np.linalg.norm(up)), 1e-12):
        return None
    forward /= size
    up = up - forward * float(np.dot(up, forward))
    return forward, up / np.linalg.norm(up)


# A foot this nearly as long as its shin (a share of the shin's length) has the length an importer gives a bone it
# read no tail for, the bone above's: Blender's glTF importer, and its FBX importer where the exporter wrote no leaf
# bones, so end a baked MMD model's deform ankle (``足首D``) 0.43 m ahead of it, as long as its shin, where its toe is
# 0.15 m ahead.
GUESSED_LENGTH = 1e-3


def guessed_foot(rig: Rig, foot: int, shin: int) -> bool:
    """Whether ``rig``'s ``foot`` bone is as long as its ``shin`` to :data:`GUESSED_LENGTH`: its tail an importer's
    guess, no toe."""
    return abs(float(rig.lengths[foot]) - float(rig.lengths[shin])) <= GUESSED_LENGTH * float(rig.lengths[shin])


def toe_across(along: np.ndarray, forward: np.ndarray) -> bool:
    """Whether a foot's tail direction ``along`` ``[3]`` is no toe: more than :data:`ACROSS_DEG` off the way the
    body faces (a foot's tail points forward and a little down, which is 70 degrees or so off its shin's line, so the
    shin is no line to judge it by)."""
    return points_across(along, forward)


def _rest_body(rig: Rig, anchors: Anchors):
    """:func:`facing_and_up` of the rig's canonical joints at rest."""
    return facing_and_up(dict(zip(JOINTS, anchor_positions(rig, anchors, rig.rest[None])[0])))


def tips_along_the_limb(rig: Rig, anchors: Anchors) -> Rig:
    """``rig`` with each finger tip that sits at a hand's tail pointing across the hand (:data:`ACROSS_DEG` off the
    forearm's line at rest) put along the forearm's line instead, :data:`HAND_TO_FOREARM` of its length past the
    wrist, turning with the hand (:attr:`Rig.tails`): where the hand has no finger bone, that is where its fingers
    go, as a BVH file's estimated finger tip (:func:`rigs.canonical_positions`). Read at those tails, every hand of
    a Bandai take imported by Blender and moved onto a rig was held a quarter turn off its forearm. Likewise each toe
    at a foot's tail that points across the way the body faces (:func:`toe_across`), or that an importer guessed
    (:func:`guessed_foot`), is put at the ball of the foot, :data:`FOOT_FORWARD` of the shin's length forward of the
    ankle and :data:`FOOT_DROP` down: where the foot has no toe bone, nothing else marks where its toes go, and read at
    that tail the foot turned a quarter turn (at a guessed tail, a baked MMD model's toe sank 4 cm)."""
    tails = rig.tails.copy()
    body = None
    for side in "lr":
        t, f, k = (JOINT_INDEX[f"{side}_{j}"] for j in ("toe", "foot", "knee"))
        foot, shin = int(anchors.bone[f]), int(anchors.bone[k])
        if not anchors.tail[t] or int(anchors.bone[t]) != foot or anchors.tail[f] or anchors.tail[k]:
            continue
        body = body or _rest_body(rig, anchors)
        if body is None or not (toe_across(rig.rest[foot, :3, :3] @ rig.tails[foot], body[0])
                                or guessed_foot(rig, foot, shin)):
            continue
        length = float(np.linalg.norm(rig.rest[foot, :3, 3] - rig.rest[shin, :3, 3]))
        tails[foot] = rig.rest[foot, :3, :3].T @ ((body[0] * FOOT_FORWARD - body[1] * FOOT_DROP) * length)
    for side in "lr":
        j, w, e = (JOINT_INDEX[f"{side}_{k}"] for k in ("fingertip", "wrist", "elbow"))
        hand, arm = int(anchors.bone[w]), int(anchors.bone[e])
        if not anchors.tail[j] or int(anchors.bone[j]) != hand or anchors.tail[w] or anchors.tail[e]:
            continue
        forearm = rig.rest[hand, :3, 3] - rig.rest[arm, :3, 3]
        if points_across(rig.rest[hand, :3, :3] @ rig.tails[hand], forearm):
            tails[hand] = rig.rest[hand, :3, :3].T @ (forearm * HAND_TO_FOREARM)
    if np.array_equal(tails, rig.tails):
        return rig
    return Rig(rig.names, rig.parents, rig.rest, rig.lengths, rig.connected, tails)


def compose(loc: np.ndarray, rot: np.ndarray) -> np.ndarray:
    """Homogeneous matrices ``[..., 4, 4]`` from locations ``[..., 3]`` and rotations ``[..., 3, 3]``."""
    m = np.zeros(rot.shape[:-2] + (4, 4))
    m[..., :3, :3] = rot
    m[..., :3, 3] = loc
    m[..., 3, 3] = 1.0
    return m


def fk(rig: Rig, loc: np.ndarray, rot: np.ndarray, scale: np.ndarray | None = None) -> np.ndarray:
    """Pose matrices ``[F, B, 4, 4]`` (armature space) from local ``loc`` ``[F, B, 3]``,
    ``rot`` ``[F, B, 3, 3]`` and optional ``scale`` ``[F, B, 3]``. A connected bone's location is left out, as
    Blender leaves it out (its head stays on its parent's tail)."""
    if rig.connected.any():
        loc = np.where(rig.connected[:, None], 0.0, loc)
    basis = compose(loc, rot * scale[..., None, :] if scale is not None else rot)
    out = np.empty(basis.shape)
    for b, p in enumerate(rig.parents):
        local = rig.rel_rest[b] @ basis[:, b]
        out[:, b] = local if p < 0 else out[:, p] @ local
    return out


def anchor_positions(rig: Rig, anchors: Anchors, pose: np.ndarray) -> np.ndarray:
    """Canonical joint positions ``[F, 21, 3]`` from pose matrices ``[F, B, 4, 4]``."""
    m = pose[:, anchors.bone]  # (F, 21, 4, 4)
    offset = np.zeros((len(anchors.bone), 4))
    offset[:, :3] = np.where(anchors.tail[:, None], rig.tails[anchors.bone], 0.0)
    offset[:, 3] = 1.0
    out = np.einsum("fjab,jb->fja", m, offset)[..., :3]
    for j, (below, above, share) in anchors.between.items():
        out[:, j] = (1.0 - share) * out[:, below] + share * out[:, above]
    return out


def _kabsch(u: np.ndarray, t: np.ndarray, w: np.ndarray) -> np.ndarray:
    """Rotations ``[F, 3, 3]`` minimising sum_i w_i |R u_i - t_i|^2; ``u``, ``t`` ``[F, N, 3]``, ``w`` ``[N]``."""
    h = np.einsum("n,fni,fnj->fij", w, u, t)
    uu, _, vt = np.linalg.svd(h)
    d = np.sign(np.linalg.det(np.swapaxes(vt, -1, -2) @ np.swapaxes(uu, -1, -2)))
    fix = np.broadcast_to(np.eye(3), h.shape).copy()
    fix[:, 2, 2] = d
    return np.swapaxes(vt, -1, -2) @ fix @ np.swapaxes(uu, -1, -2)


def _twist(g: np.ndarray, axis: np.ndarray, n_local: np.ndarray, n_target: np.ndarray) -> np.ndarray:
    """Twist ``g`` ``[F, 3, 3]`` about world ``axis`` ``[F, 3]`` so ``g @ n_local`` follows ``n_target``
    (both ``[F, 3]``, un-normalised plane normals), faded out where either plane is degenerate."""
    axis = unit(axis)
    n_now = np.einsum("fij,fj->fi", g, n_local)
    strength = np.minimum(np.linalg.norm(n_now, axis=-1), np.linalg.norm(n_target, axis=-1))
    weight = np.clip((strength - _TWIST_NONE) / (_TWIST_FULL - _TWIST_NONE), 0.0, 1.0)
    a = n_now - axis * np.sum(n_now * axis, -1, keepdims=True)
    b = n_target - axis * np.sum(n_target * axis, -1, keepdims=True)
    angle = np.arctan2(np.sum(np.cross(a, b) * axis, -1), np.sum(a * b, -1))
    return rotvec_to_matrix(axis * (angle * weight)[:, None]) @ g


def _reaching(targets: np.ndarray, joint: str, head: np.ndarray, ref_anchor: np.ndarray) -> np.ndarray:
    """``targets`` with the middle joint of the limb from ``joint`` (a knee, an elbow; :data:`_PLANE_TWIST`) moved where
    the limb, from its root joint at ``head`` ``[F, 3]`` (where the rig has it), reaches its end joint on the rig's own
    lengths (its reference pose's joints ``ref_anchor`` ``[F, 21, 3]``): two-bone IK, bending the way the targets bend.
    Aimed at the middle joint's own target, the limb missed its end by about as far as its root was off (a pelvis or
    chest shaped unlike the motion's: a foot 0.6 cm from the motion's on a CMU take's pelvis) or as its lengths
    differ from the rig's (Denoise moving a knee and not the foot: a clean take's foot played 1 cm off). A nearly
    straight limb would bend far to take up a little (a knee 4.7 cm for a leg 0.5 cm shorter), so the middle joint
    moves at most :data:`_REACH_GIVE` times as far as the end would have missed; a limb the targets hold straight, or
    that cannot reach, keeps its targets."""
    mid, end = (JOINT_INDEX[n] for n in _PLANE_TWIST[joint])
    root = JOINT_INDEX[joint]
    l1 = np.linalg.norm(ref_anchor[:, mid] - ref_anchor[:, root], axis=-1)
    l2 = np.linalg.norm(ref_anchor[:, end] - ref_anchor[:, mid], axis=-1)
    to_end = targets[:, end] - head
    d = np.linalg.norm(to_end, axis=-1)
    axis = to_end / np.maximum(d, 1e-12)[:, None]
    bend = targets[:, mid] - head
    bend = bend - axis * np.sum(bend * axis, -1, keepdims=True)
    side = np.linalg.norm(bend, axis=-1)
    along = (l1 ** 2 - l2 ** 2 + d ** 2) / (2.0 * np.maximum(d, 1e-12))
    height = np.sqrt(np.maximum(l1 ** 2 - along ** 2, 0.0))
    reached = head + axis * along[:, None] + bend / np.maximum(side, 1e-12)[:, None] * height[:, None]
    # where the end lands aimed at the middle joint's target, and how far the middle joint would move
    knee = head + unit(targets[:, mid] - head) * l1[:, None]
    miss = np.linalg.norm(knee + unit(targets[:, end] - knee) * l2[:, None] - targets[:, end], axis=-1)
    move = np.linalg.norm(reached - targets[:, mid], axis=-1)
    share = np.minimum(1.0, _REACH_GIVE * miss / np.maximum(move, 1e-12))
    ok = (side > _IN_LINE * l1) & (d < l1 + l2) & (d > np.abs(l1 - l2))
    out = targets.copy()
    out[ok, mid] += share[ok, None] * (reached - targets[:, mid])[ok]
    return out


def _plane(p0: np.ndarray, p1: np.ndarray, p2: np.ndarray) -> np.ndarray:
    """Normal of the bend at ``p1`` ``[F, 3]``, length = sine of the bend angle."""
    return np.cross(unit(p1 - p0), unit(p2 - p1))


def _aim(rig: Rig, anchors: Anchors, joint: str, ref: tuple, head: np.ndarray, base_rot: np.ndarray,
         targets: np.ndarray) -> np.ndarray:
    """Global rotation ``[F, 3, 3]`` of the bone at ``joint`` pointing at its canonical children.

    ``ref`` = (reference pose ``[F, B, 4, 4]``, reference anchors ``[F, 21, 3]``); ``head`` ``[F, 3]``
    is where the bone's head is now, ``base_rot`` its orientation with its reference local rotation."""
    ref_pose, ref_anchor = ref
    b = int(anchors.bone[JOINT_INDEX[joint]])
    kids = _carried(anchors, joint)
    if not kids:
        return base_rot
    g_ref, head_ref = ref_pose[:, b, :3, :3], ref_pose[:, b, :3, 3]
    to_local = lambda p: np.einsum("fji,fnj->fni", g_ref, p - head_ref[:, None])  # (F, N, 3) in the bone's frame
    u = to_local(ref_anchor[:, kids])
    t = targets[:, kids] - head[:, None]
    if anchors.tail[JOINT_INDEX[joint]]:  # the hips at the bone's tail: the children about it
        u = u - rig.tails[b]
        t = targets[:, kids] - targets[:, [JOINT_INDEX[joint]]]
    if len(kids) > 1:
        weights = np.array([2.0] + [1.0] * (len(kids) - 1))  # the torso child first: keep the spine aimed
        return _kabsch(u, t, weights)
    g = shortest_arc(np.einsum("fij,fj->fi", base_rot, u[:, 0]), t[:, 0]) @ base_rot
    if joint in _PLANE_TWIST:
        c, d = (JOINT_INDEX[n] for n in _PLANE_TWIST[joint])
        ud = to_local(ref_anchor[:, [d]])[:, 0]
        n_local = _plane(np.zeros_like(u[:, 0]), u[:, 0], ud)
        n_target = _plane(head, targets[:, c], targets[:, d])
        g = _twist(g, t[:, 0], n_local, n_target)
    return g


def _carried(anchors: Anchors, joint: str) -> list[int]:
    """The joints the bone at ``joint`` points at: its canonical children, a placed child (:data:`PLACED`) by its
    own children in its place (the torso child first)."""
    out = []
    for c in CHILDREN[joint]:
        out += _carried(anchors, c) if JOINT_INDEX[c] in anchors.between else [JOINT_INDEX[c]]
    return out


def _bridges(rig: Rig, anchors: Anchors, joint_at: dict[int, str]) -> dict[int, list[int]]:
    """{bone: joint indices} for unmapped bones that carry canonical joints directly (as the
    parent of their bones, or by their tail) strictly below the canonical parent's bone."""
    out: dict[int, list[int]] = {}
    for j, name in enumerate(JOINTS):
        parent = PARENT_NAMES[name]
        if parent is None or j in anchors.between:
            continue
        c = int(anchors.bone[j])
        b = c if anchors.tail[j] else int(rig.parents[c])
        top = int(anchors.bone[JOINT_INDEX[parent]])  # a placed parent's is the bone carrying it
        if b >= 0 and b not in joint_at and b != top and rig.is_ancestor(top, b):
            out.setdefault(b, []).append(j)
    return out


def _with_ancestors(rig: Rig, b: int) -> list[int]:
    """Bone ``b`` and every bone above it."""
    out = []
    while b >= 0:
        out.append(b)
        b = int(rig.parents[b])
    return out


def _in_line(rig: Rig, anchors: Anchors, b: int, joints: list[int]) -> bool:
    """Whether bridge ``b`` (:func:`_bridges`) carries one joint from a head that is, at rest, at that joint or on
    the line to it from the head of the bone the joint's parent is on: an arm's twist bone part way along the upper
    arm, an MMD model's shoulder or waist cancel bone at the joint. The bone above, aimed at the joint, aims such a
    bridge too; aimed again from part way along, at a joint the bone above does not reach, it turned half a circle
    (an MMD model's forearm came 22 cm off), and one at the joint has no aim at all."""
    if len(joints) != 1:
        return False
    j = joints[0]
    c, top = int(anchors.bone[j]), int(anchors.bone[JOINT_INDEX[PARENT_NAMES[JOINTS[j]]]])
    joint = rig.rest[c, :3, 3] + (rig.rest[c, :3, :3] @ rig.tails[c] if anchors.tail[j] else 0.0)
    to_joint, along = joint - rig.rest[b, :3, 3], joint - rig.rest[top, :3, 3]
    size, reach = max(float(np.linalg.norm(along)), 1e-12), float(np.linalg.norm(to_joint))
    if reach < _IN_LINE * size:
        return True
    return float(np.linalg.norm(np.cross(to_joint, along))) < _IN_LINE * size * reach and \
        float(np.dot(to_joint, along)) > 0.0


def _aim_bridge(ref: tuple, b: int, joints: list[int], head: np.ndarray, base_rot: np.ndarray,
                targets: np.ndarray) -> np.ndarray:
    """Global rotation ``[F, 3, 3]`` of unmapped bone ``b`` pointing at the canonical ``joints`` it carries."""
    ref_pose, ref_anchor = ref
    g_ref, head_ref = ref_pose[:, b, :3, :3], ref_pose[:, b, :3, 3]
    u = np.einsum("fji,fnj->fni", g_ref, ref_anchor[:, joints] - head_ref[:, None])  # (F, N, 3)
    t = targets[:, joints] - head[:, None]
    if len(joints) > 1:
        return _kabsch(u, t, np.ones(len(joints)))
    return shortest_arc(np.einsum("fij,fj->fi", base_rot, u[:, 0]), t[:, 0]) @ base_rot


def hips_carrier(rig: Rig, hips: int) -> int | None:
    """The bone that moves the ``hips`` bone where that is connected to its parent (its location does nothing: a
    BVH whose root is a bone on the floor with the hips its only child, as Character Creator's ``RL_BoneRoot``, imports
    so): the nearest bone above it that is not connected; None where the hips bone moves itself."""
    if not rig.connected[hips]:
        return None
    b = hips
    while rig.connected[b]:
        b = int(rig.parents[b])
    return b


def _carry(rig: Rig, pose: np.ndarray, loc: np.ndarray, carrier: int, b: int, base: np.ndarray,
           move: np.ndarray) -> np.ndarray:
    """Move bone ``carrier`` by ``move`` ``[F, 3]`` (armature space) in ``loc`` and, with it, the pose matrices of it
    and of the bones below it solved so far (those before ``b``); returns ``base`` ``[F, 4, 4]`` (bone ``b``'s, below
    the carrier) moved as far."""
    p = int(rig.parents[carrier])
    above = np.broadcast_to(rig.rel_rest[carrier] if p < 0 else pose[:, p] @ rig.rel_rest[carrier], base.shape)
    loc[:, carrier] += np.einsum("fji,fj->fi", above[:, :3, :3], move)
    for k in range(carrier, b):
        if rig.is_ancestor(carrier, k):
            pose[:, k, :3, 3] += move
    base = np.array(base)
    base[:, :3, 3] += move
    return base


def solve(rig: Rig, anchors: Anchors, targets: np.ndarray, ref_loc: np.ndarray,
          ref_rot: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Local bone transforms that put the rig's canonical joints on ``targets``.

    ``targets``: ``[F, 21, 3]`` armature space. ``ref_loc`` ``[F, B, 3]`` and ``ref_rot``
    ``[F, B, 3, 3]``: the reference local pose (the original frames, or the pose to hold):
    unmapped bones keep it, mapped bones swing from it. Returns local ``loc`` ``[F, B, 3]``
    (only the hips bone's changes, or where that is connected its carrier's: :func:`hips_carrier`) and ``rot``
    ``[F, B, 3, 3]``.
    """
    targets = np.asarray(targets, dtype=np.float64)
    joint_at = anchors.on_bones()
    bridges = _bridges(rig, anchors, joint_at)
    # a pose read in float32, made rotations again where a solved bone reads it (the solved bones and the bones above
    # them), so that no chain grows its error; the other bones (fingers, a face) only hold it
    chain = sorted({a for b in set(joint_at) | set(bridges) for a in _with_ancestors(rig, b)})
    ref_rot = np.array(ref_rot, dtype=np.float64)
    ref_rot[:, chain] = nearest_rotation(ref_rot[:, chain])
    ref_pose = fk(rig, ref_loc, ref_rot)
    ref = (ref_pose, anchor_positions(rig, anchors, ref_pose))
    hips = int(anchors.bone[JOINT_INDEX["hips"]])
    carrier = hips_carrier(rig, hips)
    loc, rot = np.array(ref_loc, dtype=np.float64), ref_rot.copy()
    pose = np.empty(ref_pose.shape)
    for b, p in enumerate(rig.parents):
        base = rig.rel_rest[b] if p < 0 else pose[:, p] @ rig.rel_rest[b]  # (F, 4, 4) or (4, 4)
        base = np.broadcast_to(base, pose[:, b].shape)
        r_base, t_base = base[:, :3, :3], base[:, :3, 3]
        if b == hips and carrier is not None:  # connected: the bone above that can move takes it to the target
            loc[:, b] = 0.0
            base = _carry(rig, pose, loc, carrier, b, base, targets[:, JOINT_INDEX["hips"]] - t_base)
            t_base = base[:, :3, 3]
        elif b == hips:
            loc[:, b] = np.einsum("fji,fj->fi", r_base, targets[:, JOINT_INDEX["hips"]] - t_base)
        head = t_base + np.einsum("fij,fj->fi", r_base, loc[:, b])
        base_rot = r_base @ rot[:, b]
        if b in joint_at:
            aimed = _reaching(targets, joint_at[b], head, ref[1]) if joint_at[b] in _PLANE_TWIST else targets
            g = _aim(rig, anchors, joint_at[b], ref, head, base_rot, aimed)
            rot[:, b] = np.swapaxes(r_base, -1, -2) @ g
            if b == hips and anchors.tail[JOINT_INDEX["hips"]]:  # the hips at the tail: the head goes where that
                head = targets[:, JOINT_INDEX["hips"]] - g @ rig.tails[b]  # puts the tail on its target
                if carrier is not None:
                    base = _carry(rig, pose, loc, carrier, b, base, head - t_base)
                else:
                    loc[:, b] = np.einsum("fji,fj->fi", r_base, head - t_base)
        elif b in bridges and not _in_line(rig, anchors, b, bridges[b]):  # an unmapped bone just above joints (a
            g = _aim_bridge(ref, b, bridges[b], head, base_rot, targets)  # clavicle, a pelvis): aim it at them
            rot[:, b] = np.swapaxes(r_base, -1, -2) @ g
        pose[:, b] = base @ compose(loc[:, b], rot[:, b])
    return loc, rot


def solved_bones(rig: Rig, anchors: Anchors) -> list[int]:
    """Bones whose rotation :func:`solve` sets (the others keep their reference pose), parents first."""
    joint_at = anchors.on_bones()
    return sorted(set(joint_at) | set(_bridges(rig, anchors, joint_at)))
