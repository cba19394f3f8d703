"""Rendering many takes to videos at once, on a Dask cluster: a studio's overnight batch.

Each take is one task, a pure function of (take, face, settings) to an MP4 and its sha256, so a
task can run on any worker, be retried, and give the very bytes a serial render gives. A worker
is a process with its own headless EGL context (the renderer's); it keeps the face and its
runtime between tasks, so only the first take on a worker pays for loading them. A take that
fails (a corrupt .fap, a missing file) comes back as a result with its one-line error; the
other takes go on.

A local cluster's workers each start cold (import facepuppet, load the face, build its runtime),
and the serial loop already keeps more than one core busy (llvmpipe's threads, the encoder), so a
small batch renders sooner one take after another: ``choose_runner`` picks serial below
``DASK_MIN_FRAMES`` frames in all or on fewer than ``DASK_MIN_CORES`` cores, and says which it chose
and why. Asking for ``workers`` or a ``scheduler`` always runs on Dask: by default the takes run on
a ``LocalCluster`` of one single-threaded worker process per core; ``scheduler`` names an existing
cluster's scheduler (``tcp://host:8786``) instead, whose workers must see the same paths (a shared
disk) and have facepuppet installed with the ``batch`` extra.
"""

from __future__ import annotations

import functools
import hashlib
import itertools
import os
import warnings
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from pathlib import Path

from puppet.errors import PuppetError
from puppet.face.load import load_face
from puppet.face.model import Face, FaceFileError, MissingFeaturePointsError
from puppet.face.rig import RigError
from puppet.io.fapfile import FapError, FapReader
from puppet.io.takes import TakeError, take_fap
from puppet.runtime.runtime import Runtime
from puppet.view.rendertake import render_take

TAKE_ERRORS = (FapError, TakeError, FaceFileError, MissingFeaturePointsError, RigError, OSError)
"""What a bad take, face or path raises: reported in the take's result, not raised."""


WORKER_ENV = {"LP_NUM_THREADS": "1"}
"""Environment of local workers: llvmpipe (a software GL) draws on one thread, since there is
one worker per core already; a GPU's driver ignores it."""


DASK_MIN_CORES = 4
"""Below this many cores a local cluster never paid (measured on 2 cores, 1 to 12 takes of 98
frames, each run a fresh process as the CLI is: Dask took 1.6-2x as long as the serial loop),
since the serial loop keeps 1.2 cores busy already."""

DASK_MIN_FRAMES = 500
"""Frames in all (640x480) below which the serial loop is chosen: a cold local cluster costs about
4.5 s more than the serial loop's start (measured: one 98-frame take, 9.6 s on Dask, 5.1 s serial),
which the batch must win back at 28 ms a frame; on 4 cores with 1.2 busy in the loop that takes
about 230 frames, and 500 leaves room for a busy machine."""


class BatchError(PuppetError, ValueError):
    """A batch that cannot start: two takes that would write the same video, no dask."""


@dataclass(frozen=True)
class RenderSettings:
    """How every take of a batch is drawn: video size, camera view, fps (None: the take's),
    the face (a face folder or mesh path; None: the embedded face) and the antialiasing post
    pass (None: this GL's default, ``renderer.choose_antialias``)."""

    size: tuple[int, int] = (640, 480)
    view: str = "front"
    fps: float | None = None
    face: str | None = None
    antialias: str | None = None


@dataclass(frozen=True)
class TakeResult:
    """One take's outcome: the video written, its frame count and sha256, or the error."""

    take: str
    video: str
    frames: int = 0
    sha256: str | None = None
    error: str | None = None

    @property
    def ok(self) -> bool:
        return self.error is None


def video_path(take: str | os.PathLike, out_dir: str | os.PathLike) -> Path:
    """Where a take's video goes: ``out_dir`` / the take's name (file stem or folder) .mp4."""
    return Path(out_dir) / f"{Path(take).stem}.mp4"


def render_task(take: str, out_dir: str, settings: RenderSettings) -> TakeResult:
    """Render one take into ``out_dir``: the task every worker runs (and a serial loop too)."""
    video = video_path(take, out_dir)
    try:
        face, runtime = _face_and_runtime(settings.face)
        frames = render_take(take, video, face=face, runtime=runtime, size=settings.size,
                             view=settings.view, fps=settings.fps, progress=False, antialias=settings.antialias)
    except TAKE_ERRORS as exc:
        return TakeResult(str(take), str(video), error=_one_line(exc, take))
    return TakeResult(str(take), str(video), frames, sha256_file(video))


def render_serial(takes: Iterable[str], out_dir: str, settings: RenderSettings, *,
                  on_result: Callable[[TakeResult], None] | None = None) -> list[TakeResult]:
    """Every take, one after another in this process: the reference a batch must equal (and
    what a small batch runs, ``choose_runner``). ``on_result`` sees each result as it is made."""
    takes = check_takes(takes, out_dir)
    Path(out_dir).mkdir(parents=True, exist_ok=True)
    results = []
    for take in takes:
        results.append(render_task(take, out_dir, settings))
        if on_result is not None:
            on_result(results[-1])
    return results


def render_batch(takes: Iterable[str], out_dir: str, settings: RenderSettings, *,
                 scheduler: str | None = None, workers: int | None = None,
                 on_result: Callable[[TakeResult], None] | None = None) -> list[TakeResult]:
    """Render every take on a Dask cluster; results in the takes' order.

    ``scheduler`` None starts a ``LocalCluster`` of ``workers`` (default: one per core)
    single-threaded worker processes for this batch; otherwise the address of a running
    scheduler. ``on_result`` sees each result as it completes (for progress lines). A take
    that fails is a result with ``error`` set; a task that dies for another reason (a worker
    lost, a bug) is reported the same way, its exception in one line.
    """
    takes = check_takes(takes, out_dir)
    Path(out_dir).mkdir(parents=True, exist_ok=True)
    try:
        from dask.distributed import Client, LocalCluster, as_completed
    except ModuleNotFoundError as exc:
        raise BatchError("rendering many takes needs dask.distributed: "
                         "pip install 'facepuppet[batch]'") from exc
    if scheduler is None:
        cluster = LocalCluster(n_workers=workers or os.cpu_count() or 1, threads_per_worker=1,
                               processes=True, dashboard_address=None, env=WORKER_ENV)
        client = Client(cluster)
    else:
        cluster, client = None, Client(scheduler)
    try:
        futures = {client.submit(render_task, take, str(out_dir), settings, pure=False): i
                   for i, take in enumerate(takes)}
        results: list[TakeResult | None] = [None] * len(takes)
        for future in as_completed(futures):
            i = futures[future]
            results[i] = _outcome(future, takes[i], out_dir)
            if on_result is not None:
                on_result(results[i])
        return results
    finally:
        client.close()
        if cluster is not None:
            cluster.close()


@dataclass(frozen=True)
class Runner:
    """How a batch runs: ``dask`` or not, with how many local ``workers`` (None: the default or
    the scheduler's), and ``why``, in words for the terminal."""

    dask: bool
    workers: int | None
    why: str


def choose_runner(takes: list[str], *, scheduler: str | None = None, workers: int | None = None,
                  cores: int | None = None) -> Runner:
    """Dask when asked for (``scheduler`` or ``workers``), else when the batch is big enough to
    pay for a local cluster's start (module docstring); the serial loop otherwise."""
    if scheduler is not None:
        return Runner(True, None, f"on the Dask scheduler at {scheduler}")
    if workers is not None:
        return Runner(True, workers, f"on a local Dask cluster of {workers} worker(s), as asked")
    cores = cores or os.cpu_count() or 1
    frames = sum(_frames_up_to(take, DASK_MIN_FRAMES) for take in takes)
    counted = f"{frames} frames" if frames < DASK_MIN_FRAMES else f"{DASK_MIN_FRAMES}+ frames"
    if len(takes) < 2 or cores < DASK_MIN_CORES or frames < DASK_MIN_FRAMES:
        return Runner(False, None, f"one after another ({counted} on {cores} core(s): a local Dask cluster pays "
                                   f"from {DASK_MIN_FRAMES} frames on {DASK_MIN_CORES}+ cores; --workers N for one)")
    workers = min(cores, len(takes))
    return Runner(True, workers, f"on a local Dask cluster of {workers} workers ({counted} on {cores} cores)")


def _frames_up_to(take: str, most: int) -> int:
    """A take's frame count (its header's, else counted up to ``most``); 0 for a take that cannot
    be read (its render says why)."""
    try:
        with warnings.catch_warnings(), FapReader(take_fap(take)) as reader:
            warnings.simplefilter("ignore")  # said by the take's render, once
            declared = reader.header.declared_frames
            return declared if declared is not None else sum(1 for _ in itertools.islice(reader, most))
    except TAKE_ERRORS:
        return 0


def sha256_file(path: str | os.PathLike) -> str:
    """Hex sha256 of a file's bytes."""
    digest = hashlib.sha256()
    with open(path, "rb") as file:
        for block in iter(lambda: file.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


@functools.lru_cache(maxsize=4)
def _face_and_runtime(face_path: str | None) -> tuple[Face, Runtime]:
    """The face and its runtime, loaded once per worker process and face."""
    face = load_face() if face_path is None else load_face(face_path)
    return face, Runtime(face)


def check_takes(takes: Iterable[str], out_dir: str | os.PathLike) -> list[str]:
    """The takes as a list; a BatchError if two would write the same video."""
    takes = [str(take) for take in takes]
    seen: dict[Path, str] = {}
    for take in takes:
        video = video_path(take, out_dir)
        if video in seen:
            raise BatchError(f"{seen[video]} and {take} would both write {video}: rename one")
        seen[video] = take
    return takes


def _outcome(future, take: str, out_dir: str | os.PathLike) -> TakeResult:
    """A finished future's TakeResult; an exception it raised, as that take's error."""
    if future.status == "finished":
        return future.result()
    exc = future.exception()
    return TakeResult(take, str(video_path(take, out_dir)), error=f"{take}: {type(exc).__name__}: {exc}")


def _one_line(exc: BaseException, take: str) -> str:
    """An error as one line that names the take (file errors often name only their path)."""
    if isinstance(exc, OSError) and not isinstance(exc, PuppetError):
        return f"{exc.filename or take}: {exc.strerror or exc}"
    message = " ".join(str(exc).split())
    return message if str(Path(take).name) in message else f"{take}: {message}"
