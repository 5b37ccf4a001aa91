"""Long work as generators, so that a caller can show progress and stop it part way.

A step generator yields as it goes (a stage's name, or the fraction of the work done as a
float in [0, 1]) and returns its result. :func:`drive` runs one to the end; an interactive
caller instead calls ``next`` on it between other work (Blender: from a timer), and closes
it to stop, which runs the generator's ``finally`` clauses.
"""

from __future__ import annotations

from collections.abc import Callable, Generator
from typing import Any, TypeVar

R = TypeVar("R")


def drive(steps: Generator[Any, None, R], report: Callable[[Any], object] | None = None) -> R:
    """Run ``steps`` to the end, passing each yielded value to ``report``; returns its result."""
    while True:
        try:
            value = next(steps)
        except StopIteration as stop:
            return stop.value
        if report is not None:
            report(value)
