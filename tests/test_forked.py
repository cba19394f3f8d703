"""Pieces worked on every core (``puppet.runtime.forked``): the same results as worked here, the
first worked here, and all of them here where no process can be forked or none answers in time."""

from __future__ import annotations

import os

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
    assert all(np.array_equal(a, task(k)) for a, k in zip(forked_map(task, items), items))


def test_the_first_item_is_worked_here_and_what_it_makes_is_inherited(two_cores):
    """What the task makes on first use (here a cache) is made once, here, not in every process."""
    made: list[int] = []

    def task(k: int) -> tuple[int, int, int]:
        if not made:
            made.append(os.getpid())
        return k, os.getpid(), made[0]

    worked = forked_map(task, [0, 1, 2, 3])
    assert [k for k, _, _ in worked] == [0, 1, 2, 3]
    assert worked[0][1] == os.getpid() and all(pid != os.getpid() for _, pid, _ in worked[1:])
    assert {maker for _, _, maker in worked} == {os.getpid()}


@pytest.mark.parametrize("workers, items", [(1, [1, 2, 3]), (2, [1, 2])], ids=["one core", "two items"])
def test_nothing_is_forked_for_one_core_or_two_items(monkeypatch, workers, items):
    monkeypatch.setattr(forked, "WORKERS", workers)
    assert forked_map(lambda k: (k, os.getpid()), items) == [(k, os.getpid()) for k in items]


def test_processes_that_do_not_answer_in_time_are_given_up_and_their_items_worked_here(two_cores, monkeypatch):
    """The next call forks again as usual."""
    monkeypatch.setattr(forked, "TIMEOUT", 0.0)
    assert forked_map(lambda k: (k * k, os.getpid()), [1, 2, 3]) == [(k * k, os.getpid()) for k in (1, 2, 3)]
    monkeypatch.setattr(forked, "TIMEOUT", 60.0)
    assert [pid == os.getpid() for _, pid in forked_map(lambda k: (k, os.getpid()), [1, 2, 3])] == [True, False, False]


def test_a_task_that_raises_raises_here(two_cores):
    def task(k: int) -> int:
        if k == 2:
            raise ValueError("piece 2 is bad")
        return k

    with pytest.raises(ValueError, match="piece 2 is bad"):
        forked_map(task, [1, 2, 3])
