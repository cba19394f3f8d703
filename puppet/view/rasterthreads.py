"""Keeping llvmpipe's rasteriser threads on cores of their own.

Mesa's llvmpipe rasterises a frame on one thread per core ("llvmpipe-0", "llvmpipe-1", ...),
woken when the frame is flushed. On the two-core machines the project is measured on, left to
the kernel, both threads often ended up sharing one core for whole runs (the waking thread's
core is the scheduler's first choice for a thread it wakes), and a 640x480 live frame then
rasterised at one core's speed: 2.1-2.3 ms instead of 1.2, in about half the processes started
(``tools/bench/latency_profile.py``). Given a core each, they rasterise in 1.2-1.3 ms in every run,
and a Sample's latency in the live loop fell from 7.5-9.0 ms median to 4.4-5.2 (``puppet bench
--only latency``, four runs each).

``spread`` pins thread k to the k-th core this process may run on (round robin); the Python
threads are left to the scheduler. Where there is a single rasteriser thread (a batch worker,
``LP_NUM_THREADS=1``) or a single core, or no ``/proc`` (not Linux), it changes nothing. The
price: a pinned thread cannot move off a core that another program keeps busy, so beside such a
program a frame waits for it; the live loop's own device processes are light (the box, 200
readings/s, took the latency's p99 from 13.2-15.6 ms to 9.7-12.6 all the same).
"""

from __future__ import annotations

import os
import re
from pathlib import Path

THREAD_NAME = re.compile(r"llvmpipe-(\d+)")
"""How Mesa names llvmpipe's rasteriser threads (the thread's ``comm``)."""


def rasteriser_threads() -> dict[int, int]:
    """{thread id: rasteriser number} of this process's llvmpipe threads (empty off Linux)."""
    threads = {}
    for task in Path("/proc/self/task").glob("*"):
        try:
            name = (task / "comm").read_text().strip()
        except OSError:  # the thread ended meanwhile
            continue
        match = THREAD_NAME.fullmatch(name)
        if match:
            threads[int(task.name)] = int(match.group(1))
    return threads


def spread() -> dict[int, int]:
    """Pin each llvmpipe rasteriser thread of this process to a core of its own (module
    docstring); returns {thread id: core} of those pinned (empty where nothing was)."""
    if not hasattr(os, "sched_setaffinity"):
        return {}
    cores = sorted(os.sched_getaffinity(0))
    threads = rasteriser_threads()
    if len(cores) < 2 or len(set(threads.values())) < 2:
        return {}
    pinned = {}
    for thread, number in threads.items():
        core = cores[number % len(cores)]
        try:
            os.sched_setaffinity(thread, {core})
        except OSError:  # the thread ended, or the system does not let us
            continue
        pinned[thread] = core
    return pinned
