"""Step generators: a part of larger work reports its fractions as a share of the whole."""

from __future__ import annotations

from model_core.inference.steps import drive, share


def counted(n: int):
    for k in range(1, n + 1):
        yield k / n
    yield "named"
    return n


def test_a_share_maps_the_fractions_into_its_part_and_keeps_the_result_and_other_values():
    seen = []
    assert drive(share(counted(4), 0.5, 0.25), seen.append) == 4
    assert seen == [0.5625, 0.625, 0.6875, 0.75, "named"]


def test_closing_a_share_closes_the_work_it_runs():
    closed = []

    def work():
        try:
            yield 0.5
            yield 1.0
        finally:
            closed.append(True)

    inner = work()
    steps = share(inner, 0.0, 0.5)
    assert next(steps) == 0.25
    steps.close()
    assert closed == [True]  # (``inner`` still referenced here: closed by the share, not by its collection)
