"""Pieces worked on every core (``puppet.runtime.forked``): the same results as worked here, and a
caller told to work here itself where no process can be forked or none answers in time."""

from __future__ import annotations

import numpy as np
import pytest

import puppet.runtime.forked as forked
from puppet.runtime.forked import forked_map


@pytest.fixture
def two_cores(monkeypatch):
    monkeypatch.setattr(forked, "WORKERS", 2)


def test_the_results_are_the_tasks_in_order_from_what_the_processes_inherit(two_cores):
    """The task is a closure over an array it never receives: the forked processes inherit it."""
    big = np.random.default_rng(3).normal(size=(2000, 3))

    def task(k: int) -> np.ndarray:
        return big[k::7].sum(axis=0)

    items = list(range(7))
    worked = forked_map(task, items)
    assert worked is not None
    assert all(np.array_equal(a, task(k)) for a, k in zip(worked, items))


@pytest.mark.parametrize("workers, items", [(1, [1, 2, 3]), (2, [1])], ids=["one core", "one item"])
def test_nothing_is_forked_for_one_core_or_one_item(monkeypatch, workers, items):
    monkeypatch.setattr(forked, "WORKERS", workers)
    assert forked_map(lambda k: k, items) is None


def test_processes_that_do_not_answer_in_time_are_given_up(two_cores, monkeypatch):
    """The caller then works here (``None``), and the next call forks again as usual."""
    monkeypatch.setattr(forked, "TIMEOUT", 0.0)
    assert forked_map(lambda k: k * k, [1, 2, 3]) is None
    monkeypatch.setattr(forked, "TIMEOUT", 60.0)
    assert forked_map(lambda k: k * k, [1, 2, 3]) == [1, 4, 9]


def test_a_task_that_raises_raises_here(two_cores):
    def task(k: int) -> int:
        if k == 2:
            raise ValueError("piece 2 is bad")
        return k

    with pytest.raises(ValueError, match="piece 2 is bad"):
        forked_map(task, [1, 2, 3])
