"""The command-line tools: run each by path from a checkout (``python scripts/train.py``) or, installed
with pip, as ``strnn-batch``, ``strnn-train``, ``strnn-evaluate`` and ``strnn-demo``."""
