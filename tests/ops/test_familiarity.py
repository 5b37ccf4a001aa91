"""Familiarity: the bundled model knows real takes (its shipped seed windows come from test-split
takes) and says that a procedural walk, far from any capture, is unlike what it learnt."""

from __future__ import annotations

import numpy as np

from model_core.inference.engine import Engine
from model_core.motion.features import features_to_positions, learnt_body, with_bone_lengths
from model_core.motion.synthetic import walking_skeleton
from model_core.ops import familiarity
from model_core.ops.familiarity import clip_familiarity


def test_real_takes_are_familiar_and_a_procedural_walk_is_not():
    """The seeds are test-split takes' first seconds (one per action: starts, turns, stops), rarer than the
    validation windows the 90th percentile is taken over: most, not all, read as familiar."""
    engine = Engine.load()
    usual = engine.ckpt.meta[familiarity.KEY]["reconstruction_cm_p90"]
    real = [familiarity.assess(engine, features_to_positions(seed)) for seed in engine.seeds]
    assert sum(not f.unfamiliar for f in real) > len(real) // 2 and all(f.usual_cm == usual for f in real)
    assert all(f.note() == "" for f in real if not f.unfamiliar)
    walk = familiarity.assess(engine, walking_skeleton(120))
    assert walk.unfamiliar and walk.ratio > 1.5 and "unlike what the model learnt" in walk.note()


def test_clip_familiarity_reads_any_rate_and_unit():
    engine = Engine.load()
    at30 = clip_familiarity(engine, walking_skeleton(60), 30.0)
    at60 = clip_familiarity(engine, walking_skeleton(120, fps=60.0) * 100.0, 60.0)  # centimetres at 60 fps
    assert abs(at30.error_cm - at60.error_cm) < 0.15 * at30.error_cm


def test_calibration_percentiles():
    engine = Engine.load()
    clips = [features_to_positions(np.concatenate([s, s])) for s in engine.seeds]
    record = familiarity.calibrate(engine, clips)
    assert 0 < record["reconstruction_cm_p50"] <= record["reconstruction_cm_p90"] and record["windows"] > 0


def test_a_clip_a_little_above_the_ninetieth_percentile_is_not_called_unfamiliar():
    """One clip in ten of held-back takes rebuilds worse than the 90th percentile: the note waits for a margin."""
    usual = 2.0
    assert not familiarity.Familiarity(1.1 * usual, usual).unfamiliar
    assert familiarity.Familiarity(1.3 * usual, usual).unfamiliar
    assert not familiarity.Familiarity(5.0, None).unfamiliar  # an uncalibrated model says nothing


def test_the_clip_keeps_its_momentum_only_where_the_model_does_not_know_the_motion():
    """Extend and Fill Gap let a clip's momentum carry on where the model would not continue it well: a
    walk of the test split keeps none, a procedural walk (far from any capture) all of it; an
    uncalibrated model or a context shorter than the model's window keeps none."""
    engine = Engine.load()
    names = engine.ckpt.seed_names
    walk = features_to_positions(engine.seeds[next(i for i, n in enumerate(names) if "_walk_" in n)])
    procedural = walking_skeleton(20)
    ratios = familiarity.context_ratios(engine, np.stack([walk, procedural]))
    assert ratios[0] < 1.0 < 1.5 < ratios[1]
    assert familiarity.momentum_shares(engine, np.stack([walk, procedural])) == [0.0, 1.0]
    assert familiarity.context_ratios(engine, procedural[None, :10]) is None
    assert familiarity.momentum_shares(object(), procedural[None]) == [0.0]  # no calibration to judge by


def test_a_familiar_motion_on_a_body_of_other_proportions_is_still_familiar(monkeypatch):
    """Familiarity judges the motion, not the body: the seed walks on a body with a long chest, a short lower
    spine and long thighs (as a generated Rigify rig reads through the bone map) read as they did, where the
    model's plain reconstruction of them would call most of them unfamiliar."""
    engine = Engine.load()
    seeds = [features_to_positions(seed) for seed in engine.seeds]
    stretch = np.ones(21)
    stretch[[1, 2, 6, 7, 10, 11]] = [0.85, 3.0, 1.1, 0.9, 1.1, 0.9]  # spine, spine1, thighs and shins
    other = [with_bone_lengths(s, learnt_body(engine.seeds) * stretch) for s in seeds]
    same = [familiarity.assess(engine, s).ratio for s in seeds]
    moved = [familiarity.assess(engine, o).ratio for o in other]
    np.testing.assert_allclose(moved, same, rtol=0.1)
    monkeypatch.setattr(familiarity, "on_model_body", lambda engine, pos: np.asarray(pos))  # the body as it is
    plain = [familiarity.assess(engine, o).ratio for o in other]
    assert np.median(plain) > 1.5 * np.median(same)
