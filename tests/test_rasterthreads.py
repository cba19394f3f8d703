"""llvmpipe's rasteriser threads get a core each (``puppet.view.rasterthreads``): each run in a
fresh interpreter, since a thread's affinity is the process's state."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

AFFINITIES = """
import json, os
import trimesh
from puppet.view import rasterthreads
from puppet.view.renderer import Renderer

sphere = trimesh.creation.icosphere(subdivisions=2)
with Renderer(sphere.faces, len(sphere.vertices), width=32, height=32) as renderer:
    renderer.render(sphere.vertices)
    threads = rasterthreads.rasteriser_threads()
    print(json.dumps({"process": sorted(os.sched_getaffinity(0)),
                      "threads": [[n, sorted(os.sched_getaffinity(t))] for t, n in threads.items()],
                      "renderer": renderer.ctx.info["GL_RENDERER"]}))
"""


def _affinities(**env: str) -> dict:
    result = subprocess.run([sys.executable, "-c", AFFINITIES], capture_output=True, text=True, check=True,
                            cwd=ROOT, env={**os.environ, "PYTHONPATH": str(ROOT), **env}, timeout=120)
    return json.loads(result.stdout.strip().splitlines()[-1])


def test_each_rasteriser_thread_gets_a_core_of_its_own() -> None:
    """A renderer on llvmpipe pins its rasteriser threads one to a core, the k-th thread to the
    k-th core the process may use; on one core there is nothing to spread."""
    seen = _affinities()
    assert "llvmpipe" in seen["renderer"].lower()
    cores, threads = seen["process"], seen["threads"]
    assert len(threads) >= 1
    if len(cores) < 2 or len(threads) < 2:
        assert all(affinity == cores for _, affinity in threads)
        return
    for number, affinity in threads:
        assert affinity == [cores[number % len(cores)]]
    assert len({affinity[0] for _, affinity in threads}) == min(len(threads), len(cores))


def test_a_single_rasteriser_thread_is_left_to_the_scheduler() -> None:
    """One rasteriser thread (a batch worker's ``LP_NUM_THREADS=1``) is not pinned: several
    such processes must not all crowd onto the first core."""
    seen = _affinities(LP_NUM_THREADS="1")
    assert [number for number, _ in seen["threads"]] == [0]
    assert seen["threads"][0][1] == seen["process"]
