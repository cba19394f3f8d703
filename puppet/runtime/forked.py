"""Independent pieces of a rig's set-up worked on every core, in processes forked from this one.

``puppet rig`` spends its seconds on pieces that do not depend on each other: the fold-limit
search's ends (``puppet.runtime.foldsearch``), the expressions and visemes checked for creases
and folds (``puppet.runtime.creasesmoothing``, ``puppet.runtime.posecheck``). A forked process
inherits the runtime and everything the piece needs, so nothing is sent to it but an item's
index, and nothing comes back but its result.

Python 3.12+ warns that a process with threads may deadlock a forked child: here the threads are
numpy's BLAS pool, which OpenBLAS stops before a fork and starts again as needed, and after
``meshlandmarks``' renders the GL driver's, which the children never touch. The warning is not
shown, and processes that have not answered within ``TIMEOUT`` are given up: their items are then
worked here.
"""

from __future__ import annotations

import multiprocessing
import os
import warnings
from collections.abc import Callable, Sequence
from typing import Any, TypeVar

Item = TypeVar("Item")
Result = TypeVar("Result")

WORKERS = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1
"""Processes ``forked_map`` works in: the cores this process may run on."""
TIMEOUT = 120.0
"""Seconds ``forked_map`` waits for its processes (ICT's pieces take 0.1-3 s) before giving up."""
_TASK: tuple[Callable[[Any], Any], Sequence[Any]] | None = None
"""(the task, its items) that the forked processes inherit (set only while they run)."""


def forked_map(task: Callable[[Item], Result], items: Sequence[Item]) -> list[Result]:
    """``[task(item) for item in items]``: the first item worked here, so that what the task makes
    on first use (a runtime's FAP engine, a check's reference) is made once and inherited, the
    others in up to ``WORKERS`` processes forked from this one. ``task`` may be a closure: it is
    inherited, not sent. With one core, fewer than three items, no ``fork`` on this system, or no
    answer within ``TIMEOUT``, the others are worked here too."""
    done = [task(item) for item in items[:1]]
    rest = _forked(task, items[1:]) if len(items) > 2 else None
    return done + (rest if rest is not None else [task(item) for item in items[1:]])


def _forked(task: Callable[[Item], Result], items: Sequence[Item]) -> list[Result] | None:
    """``task`` over ``items`` in forked processes, or None where they cannot be (``forked_map``)."""
    if WORKERS < 2 or "fork" not in multiprocessing.get_all_start_methods():
        return None
    global _TASK
    _TASK = (task, items)
    try:
        with warnings.catch_warnings():
            warnings.filterwarnings("ignore", r"This process .* is multi-threaded", DeprecationWarning)
            pool = multiprocessing.get_context("fork").Pool(min(WORKERS, len(items)))
        with pool:
            return pool.map_async(_worked, range(len(items)), chunksize=1).get(TIMEOUT)
    except multiprocessing.TimeoutError:
        return None
    finally:
        _TASK = None


def _worked(index: int) -> Any:
    """Item ``index``'s result, in a forked process, from the task it inherited."""
    task, items = _TASK
    return task(items[index])
