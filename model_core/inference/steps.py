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


def share(steps: Generator[Any, None, R], start: float, width: float) -> Generator[Any, None, R]:
    """``yield from`` ``steps``, a part of larger work: each fraction it yields mapped to ``start + width *
    fraction`` (other values as they are); returns its result. Closed, it closes ``steps``."""
    try:
        while True:
            try:
                value = next(steps)
            except StopIteration as stop:
                return stop.value
            yield start + width * value if isinstance(value, float) else value
    finally:
        steps.close()
