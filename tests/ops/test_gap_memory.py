"""Fill Gap follows the take: the stretch of the take outside the gap that fits both of its ends is found (as
it is or mirrored), placed where the context ends, and leant on as far as it fits; a take that never did
what the gap must is not leant on; the gap still arrives at its target."""

from __future__ import annotations

import numpy as np

from model_core.eval.inbetween_evaluation import interpolate
from model_core.inference.engine import Engine
from model_core.motion.features import mirror_positions
from model_core.motion.synthetic import walking_skeleton
from model_core.ops import gap_memory
from model_core.ops.inbetween import inbetween, inbetween_positions, with_take


def error_cm(a: np.ndarray, b: np.ndarray) -> float:
    return float(100 * np.linalg.norm(a - b, axis=-1).mean())


def test_the_stretch_that_fits_both_ends_of_the_gap_is_found_and_placed_where_the_context_ends():
    """A periodic walk on a circle: a stretch one lap earlier is the gap's own motion, turned and moved."""
    walk = walking_skeleton(400, radius=4.0).astype(np.float64)
    start, frames = 300, 30
    context, truth, target = walk[start - 20:start], walk[start:start + frames + 1], walk[start + frames:]
    distance, stretch = gap_memory.best_stretch([walk[:start]], context, target, frames)
    assert distance < 1e-4 and gap_memory.share(distance, frames, 0.0) > 0.98
    assert stretch.shape == truth.shape
    assert error_cm(stretch, truth) < 1.0  # the same motion, where the gap is
    # a take that only ever walked on the other foot's side (mirrored) still offers the stretch
    distance_m, stretch_m = gap_memory.best_stretch([mirror_positions(walk[:start])], context, target, frames)
    assert distance_m < 1e-4 and error_cm(stretch_m, truth) < 1.0


def test_segments_too_short_for_the_gap_offer_nothing():
    walk = walking_skeleton(200).astype(np.float64)
    context, target = walk[80:100], walk[130:132]
    assert gap_memory.best_stretch([walk[60:100], walk[130:160]], context, target, 30) == (float("inf"), None)
    assert gap_memory.share(float("inf"), 30, 1.0) == 0.0
    # a context of fewer frames than are matched (a keyed pose or two) is not matched at all
    assert gap_memory.best_stretch([walk], context[-3:], target, 30) == (float("inf"), None)


def test_a_gap_leans_on_the_take_only_as_far_as_the_take_did_the_same():
    """The same gap filled from a take that walked it before (followed all the way: the truth) and from a take
    of a standing body (hardly leant on); either way it arrives at the target. The share falls with the fit's
    distance, in longer gaps and where the model knows the motion."""
    walk = walking_skeleton(400, radius=4.0).astype(np.float64)
    start, frames = 300, 30
    context, truth, target = walk[start - 20:start], walk[start:start + frames], walk[start + frames:start + frames + 2]
    filled = np.concatenate([interpolate(context[-1], target[0], frames), target[:1]])  # a poor fill
    followed = with_take(context, target, filled, [walk[:start], walk[start + frames:]], momentum=1.0)
    assert error_cm(followed[:-1], truth) < 0.2 * error_cm(filled[:-1], truth)
    arrival = np.linalg.norm(followed[-1] - target[0], axis=-1)
    assert arrival.mean() < 0.001 and arrival.max() < 0.02  # the bones' pass leans a straight knee a little
    stand = np.repeat(walk[:1], 200, 0)
    for momentum, most in ((0.0, 0.01), (1.0, 0.2)):  # motion the model knows, and motion it does not
        moved = error_cm(with_take(context, target, filled, [stand], momentum=momentum), filled)
        assert moved < most * error_cm(followed, filled), momentum
    np.testing.assert_array_equal(with_take(context, target, filled, None), filled)
    assert gap_memory.share(0.01, 30, 1.0) > gap_memory.share(0.01, 60, 1.0) > gap_memory.share(0.01, 60, 0.0) > 0


def test_fill_gap_follows_a_real_take_that_repeats_its_moves(mocap_root):
    """A martial-arts take (kicks and punches repeated; an action family the models never learnt): gaps of
    one and two seconds filled with the rest of the take nearer the truth than without it, and than the
    interpolation; every gap still arrives at its target."""
    from model_core.rig.rigs import load_clip

    engine = Engine.load()
    take = load_clip(mocap_root / "cmu/acrnn-dance/martial/03.bvh").astype(np.float64)
    for frames in (30, 60):
        ours, alone, lerp = [], [], []
        for s in range(0, len(take) - frames - 21, 45):
            context, truth, target = take[s:s + 20], take[s + 20:s + 20 + frames], take[s + 20 + frames:][:2]
            memory = [take[max(0, s - 580):s + 20], take[s + 20 + frames:s + 620 + frames]]
            with_memory = inbetween(engine, context, target, frames, memory)
            ours.append(error_cm(with_memory, truth))
            alone.append(error_cm(inbetween(engine, context, target, frames), truth))
            lerp.append(error_cm(interpolate(context[-1], target[0], frames), truth))
        assert len(ours) >= 5
        assert np.mean(ours) < 0.85 * np.mean(alone) and np.mean(ours) < 0.75 * np.mean(lerp), (frames, ours, alone)


def test_fill_gap_reads_the_take_either_side_at_any_rate_and_only_when_asked():
    """inbetween_positions at 60 fps, in centimetres: the take after the gap alone holds the stretch (the
    frames before it are a standing pose), and the gap follows it; without follow_take it does not."""
    walk = 100 * walking_skeleton(800, fps=60, radius=4.0).astype(np.float64)
    start, frames = 200, 59
    before = np.concatenate([np.repeat(walk[:1], start - 40, 0), walk[start - 40:start]])
    after = walk[start + frames:]
    truth = walk[start:start + frames]
    followed = inbetween_positions(Engine.load(), before, after, 60.0, frames)
    alone = inbetween_positions(Engine.load(), before, after, 60.0, frames, follow_take=False)
    assert followed.shape == alone.shape == truth.shape
    assert error_cm(followed, truth) / 100 < 0.5 * error_cm(alone, truth) / 100
