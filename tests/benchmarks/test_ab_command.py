"""The interleaved A/B timing of the whole command (`benchmarks.ab_command`)."""

from __future__ import annotations

from contextlib import ExitStack

import pytest

from benchmarks.ab_command import REPOSITORY, Run, compare, source_tree


def runs(walls: list[float]) -> list[Run]:
    return [Run(wall=w, cpu=2 * w, job=w - 0.4, loop=w - 0.6) for w in walls]


def test_pairs_are_compared_in_turn_not_as_two_sets():
    """B is faster in the pairs where its run took less than the A run just before, by
    the median of those differences, whatever each side's median says."""
    a = runs([2.0, 3.4, 2.1, 3.5, 2.2])
    b = runs([1.9, 3.3, 2.2, 3.4, 2.0])
    summary = compare(a, b)
    assert summary["wall"] == {"a": 2.2, "b": 2.2}
    assert summary["b_faster_pairs"] == 4 and summary["pairs"] == 5
    assert summary["wall_difference"] == pytest.approx(0.1)
    assert summary["cpu"]["a"] == pytest.approx(4.4)
    assert summary["loop"]["b"] == pytest.approx(1.6)


def test_unpaired_runs_are_refused():
    with pytest.raises(ValueError, match="as many runs"):
        compare(runs([2.0, 2.1]), runs([2.0]))
    with pytest.raises(ValueError, match="at least one"):
        compare([], [])


def test_a_checkout_folder_is_taken_as_it_is_and_a_bad_name_is_named():
    with ExitStack() as stack:
        assert source_tree(str(REPOSITORY), stack) == REPOSITORY.resolve()
        with pytest.raises(SystemExit, match="no-such-revision"):
            source_tree("no-such-revision", stack)
