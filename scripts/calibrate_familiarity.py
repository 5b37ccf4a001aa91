#!/usr/bin/env python3
"""Measure a model's usual reconstruction error on held-back takes and keep it in its model.json.

The operators compare a clip's reconstruction error with it to say when a clip is unlike what the
model learnt (model_core/ops/familiarity.py). Run it once per release, on takes the model did not
train on:

  python scripts/calibrate_familiarity.py --data data/mocap --split validation --checkpoint models/strnn_default
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from model_core.inference.engine import Engine  # noqa: E402
from model_core.io.checkpoint import DEFAULT_MODEL, CheckpointError  # noqa: E402
from model_core.io.files import write_json  # noqa: E402
from model_core.model.dataset import DataError, load_folder  # noqa: E402
from model_core.ops import familiarity  # noqa: E402


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--data", required=True, help="folder of .bvh files (searched recursively)")
    p.add_argument("--split", choices=("all", "train", "validation", "test"), default="validation",
                   help="which clips (the project's split rule); 'all' for a folder of held-back takes")
    p.add_argument("--checkpoint", default=str(DEFAULT_MODEL), help="release folder to calibrate")
    p.add_argument("--cache", default="data/cache", help="folder for cached dataset arrays ('' = none)")
    args = p.parse_args(argv)
    try:
        engine = Engine.load(args.checkpoint)
        data = load_folder(args.data, cache_dir=args.cache or None, progress=False)
        clips = data.clips if args.split == "all" else data.split(args.split)
        if not clips:
            raise DataError(f"{args.data}: no clips in the {args.split!r} split")
        record = familiarity.calibrate(engine, [c.positions for c in clips])
    except (CheckpointError, DataError, ValueError) as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    path = Path(args.checkpoint) / "model.json"
    doc = json.loads(path.read_text())
    doc[familiarity.KEY] = {**record, "data": f"{Path(args.data).name}, {args.split} split"}
    write_json(path, doc)
    print(f"{path}: {json.dumps(doc[familiarity.KEY])}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
