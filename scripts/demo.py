#!/usr/bin/env python3
"""The full demo on built-in data only: no input file needed.

1. Takes a 20-frame seed window shipped with the model (models/strnn_default/seeds.npz; by
   default the first taken from a walk, --seed N for another) and continues it open-loop
   with the NumPy engine (--frames, default 600).
2. Walks the evaluation figure-eight (two 2 m loops) from the last 20 frames with the NumPy
   path follower that Follow Curve runs (the path is placed under the character, so there is no
   jump). --path-frames: frames of the walk (default: one lap).
3. Foot-locks the result (contacts detected on the motion), then, as a check of Denoise,
   puts 3 cm of Gaussian jitter on every joint of it and denoises that with the bundled
   denoising model (the printed errors are against the foot-locked motion).
4. Writes into --out: demo.bvh, demo.png (stick-figure contact sheet), demo_plots.png
   (prediction error against horizon for STRNN and the baselines, from the model's
   evaluation.json; foot skate before and after the lock), demo.blend (the BVH imported into a
   fresh scene with the bpy module, with a simple body, a floor and a camera that follows the
   character: press play) and demo_render.png (--renders frames of it rendered by Blender's
   Workbench engine). The last two are skipped with a note when bpy is missing.

    python scripts/demo.py                      # the first walking seed into out/
    python scripts/demo.py --frames 90 --path-frames 60 --out out/quick
"""

from __future__ import annotations

import argparse
import importlib.util
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

import numpy as np

from model_core.eval.demo_pipeline import build_motion, denoise_check, load_evaluation, plot_demo
from model_core.io.bvh_export import write_bvh
from model_core.io.checkpoint import CheckpointError
from model_core.motion.conventions import MODEL_FPS


def parse_args(argv=None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--frames", type=int, default=600, help="frames of open-loop continuation after the seed (30 fps)")
    p.add_argument("--path-frames", type=int, default=None,
                   help="frames of the figure-eight walk (default: one lap; 0: no walk)")
    p.add_argument("--seed", type=int, default=None,
                   help="index of the shipped seed window to start from (default: the first walk)")
    p.add_argument("--model", default=None, help="model folder (default: models/strnn_default)")
    p.add_argument("--out", default="out", help="output folder for demo.bvh, demo.png, demo_plots.png, demo.blend")
    p.add_argument("--panels", type=int, default=12, help="stick figures on the contact sheet")
    p.add_argument("--no-blend", action="store_true", help="do not write demo.blend (nor render)")
    p.add_argument("--renders", type=int, default=8,
                   help="frames rendered with Blender (Workbench) into demo_render.png; 0: none")
    return p.parse_args(argv)



def write_blend(bvh: str | Path, blend: str | Path, render_dir: Path | None = None, frames: int = 8,
                timeout: float = 240.0) -> tuple[Path | None, list[tuple[int, Path]], str]:
    """Import ``bvh`` into a fresh Blender scene with a simple body, floor and following camera
    (scripts/demo_blend.py, in a child Python so that bpy's state never touches this process),
    save ``blend`` and, with ``render_dir``, render ``frames`` frames with Workbench.
    Returns (path or None, [(frame, png)], note explaining a skip or failure)."""
    if importlib.util.find_spec("bpy") is None:
        return None, [], ("the bpy module is not installed: .blend skipped (scripts/setup.sh installs it; "
                          "with pip: strnn-motion[blender])")
    shown, blend = Path(blend), Path(blend).resolve()
    blend.parent.mkdir(parents=True, exist_ok=True)
    cmd = [sys.executable, str(Path(__file__).with_name("demo_blend.py")), str(Path(bvh).resolve()), str(blend),
           "--fps", str(int(MODEL_FPS))]
    if render_dir is not None:
        cmd += ["--render-dir", str(render_dir), "--frames", str(frames)]
    try:
        done = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout)
    except subprocess.TimeoutExpired:
        return None, [], f"bpy did not finish within {timeout:.0f} s: .blend skipped"
    if done.returncode != 0 or not blend.is_file():
        tail = (done.stderr or done.stdout).strip().splitlines()[-3:]
        return None, [], "writing the .blend failed: " + " | ".join(tail)
    rendered = [(int(line.split()[1]), Path(line.split(maxsplit=2)[2])) for line in done.stdout.splitlines()
                if line.startswith("frame ")]
    return shown, rendered, ""


def render_sheet(path: Path, frames: list[tuple[int, Path]], title: str, columns: int = 4) -> Path:
    """A contact sheet of Blender renders: ``frames`` [(frame number, png)] in rows of ``columns``."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.image as mpimg
    import matplotlib.pyplot as plt

    rows = -(-len(frames) // columns)
    fig, axes = plt.subplots(rows, columns, figsize=(3.2 * columns, 2.9 * rows), squeeze=False)
    for ax in axes.flat:
        ax.axis("off")
    for ax, (frame, png) in zip(axes.flat, frames):
        ax.imshow(mpimg.imread(png))
        ax.set_title(f"frame {frame} ({(frame - 1) / MODEL_FPS:.1f} s)", fontsize=9)
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path


def main(argv=None) -> int:
    args = parse_args(argv)
    if args.frames < 1:
        print("error: --frames must be at least 1", file=sys.stderr)
        return 2
    if args.path_frames is not None and args.path_frames < 0:
        print("error: --path-frames must be 0 or more", file=sys.stderr)
        return 2
    started = time.perf_counter()
    try:
        motion = build_motion(args.model, args.seed, args.frames, args.path_frames)
    except (CheckpointError, ValueError, OSError) as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    took = time.perf_counter() - started
    if not np.all(np.isfinite(motion.locked)):
        print("error: the model produced non-finite values; nothing written", file=sys.stderr)
        return 1
    walk = len(motion.walked) - len(motion.extended)
    print(f"generated {args.frames} frames from {motion.seed_name}, then {walk} frames on the figure-eight, "
          f"foot-locked, in {took:.2f} s")
    print(f"foot skate: {motion.skate_before_cm:.2f} cm/frame before the lock, "
          f"{motion.skate_after_cm:.2f} after")
    noisy_cm, clean_cm, _ = denoise_check(motion.locked)
    print(f"denoise: 3 cm of jitter on every joint, mean joint error {noisy_cm:.2f} cm -> {clean_cm:.2f} cm")
    out = Path(args.out)
    bvh = write_bvh(out / "demo.bvh", motion.locked, fps=MODEL_FPS)
    title = (f"STRNN: {motion.seed_name} + {args.frames} frames" + (f" + {walk} on a figure-eight" if walk else "")
             + f", foot-locked ({len(motion.locked) / MODEL_FPS:.1f} s)")
    print(f"BVH: {bvh}")
    pictures = importlib.util.find_spec("matplotlib") is not None
    if pictures:
        from model_core.eval.plots import contact_sheet

        print(f"PNG: {contact_sheet(out / 'demo.png', motion.locked, count=args.panels, title=title)}")
        evaluation = load_evaluation(args.model)
        print(f"Plots: {plot_demo(out / 'demo_plots.png', evaluation, motion.skate_before_cm, motion.skate_after_cm)}")
    else:
        print("note: matplotlib is not installed: pictures skipped (scripts/setup.sh installs it; with pip: "
              "strnn-motion[plots])")
    if args.no_blend:
        print("Blend: skipped (--no-blend)")
    else:
        with tempfile.TemporaryDirectory(prefix="strnn_demo_") as tmp:
            blend, rendered, note = write_blend(bvh, out / "demo.blend", Path(tmp) if args.renders else None,
                                                args.renders)
            print(f"Blend: {blend}" if blend else f"note: {note}")
            if rendered and pictures:
                print(f"Render: {render_sheet(out / 'demo_render.png', rendered, title)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
