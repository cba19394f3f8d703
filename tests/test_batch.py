"""Batch renders on Dask: the videos are byte for byte a serial render's, and a corrupt take is
reported by name while the others are written."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from puppet.io.fapfile import read_fap, write_fap
from puppet.view import batch

distributed = pytest.importorskip("dask.distributed")

DEMO = Path(__file__).resolve().parents[1] / "puppet" / "data" / "demo_take.fap"
SETTINGS = batch.RenderSettings(size=(160, 120))


def cut(stream, start: int, frames: int):
    """Frames start..start+frames of a take, as a take of their own."""
    window = slice(start, start + frames)
    return dataclasses.replace(
        stream, values=stream.values[window], mask=stream.mask[window], viseme=stream.viseme[window],
        expression=stream.expression[window], frame_numbers=stream.frame_numbers[window] - start,
        declared_frames=frames)


@pytest.fixture(scope="module")
def takes(tmp_path_factory) -> list[str]:
    folder = tmp_path_factory.mktemp("takes")
    stream = read_fap(DEMO)
    paths = []
    for i, start in enumerate((0, 30, 60)):
        path = folder / f"take{i}.fap"
        write_fap(path, cut(stream, start, 8))
        paths.append(str(path))
    corrupt = folder / "corrupt.fap"
    corrupt.write_text(DEMO.read_text().replace("\n1 1 0", "\n1 x 0", 1))
    return paths[:2] + [str(corrupt)] + paths[2:]


@pytest.fixture(scope="module")
def serial(takes, tmp_path_factory):
    out = tmp_path_factory.mktemp("serial")
    return out, batch.render_serial(takes, str(out), SETTINGS)


def test_a_corrupt_take_is_reported_by_name_and_the_others_are_rendered(serial) -> None:
    out, results = serial
    failed = [r for r in results if not r.ok]
    assert [Path(r.take).name for r in failed] == ["corrupt.fap"]
    assert "corrupt.fap" in failed[0].error and "\n" not in failed[0].error
    assert not Path(failed[0].video).exists()
    for result in results:
        if result.ok:
            assert result.frames == 8
            assert result.sha256 == batch.sha256_file(result.video)


@pytest.mark.slow
def test_dask_batch_writes_the_serial_render_byte_for_byte(takes, serial, tmp_path, egl) -> None:
    serial_out, expected = serial
    seen = []
    results = batch.render_batch(takes, str(tmp_path), SETTINGS, workers=2, on_result=seen.append)
    assert sorted(r.take for r in seen) == sorted(takes)
    assert [r.take for r in results] == takes
    assert [r.ok for r in results] == [r.ok for r in expected]
    for got, want in zip(results, expected):
        if want.ok:
            assert got.sha256 == want.sha256
            assert Path(got.video).read_bytes() == Path(want.video).read_bytes()
        else:
            assert got.error == want.error


def test_two_takes_that_would_overwrite_one_video_are_refused(tmp_path) -> None:
    with pytest.raises(batch.BatchError, match="would both write"):
        batch.render_serial(["a/take.fap", "b/take.fap"], str(tmp_path), SETTINGS)


@pytest.mark.slow
def test_puppet_render_many_takes_into_a_folder(takes, serial, tmp_path, capsys, egl) -> None:
    from puppet import cli

    _, expected = serial
    out = tmp_path / "videos"
    assert cli.main(["render", *takes, "-o", f"{out}/", "--size", "160x120", "--workers", "2"]) == 2
    captured = capsys.readouterr()
    said, error = captured.err.splitlines()
    assert said == "rendering 4 takes on a local Dask cluster of 2 worker(s), as asked" and "corrupt.fap" in error
    for want in expected:
        if want.ok:
            video = out / Path(want.video).name
            assert f"{video}: 8 frames sha256 {want.sha256}" in captured.out
            assert batch.sha256_file(video) == want.sha256


def _still(path: Path, frames: int) -> str:
    """A take of ``frames`` frames at rest."""
    write_fap(path, (np.zeros((frames, 68)), np.ones((frames, 68), dtype=bool)), fps=25)
    return str(path)


def test_a_small_batch_renders_one_take_after_another_and_a_big_one_on_dask(tmp_path) -> None:
    """A cold local cluster costs more than a small batch gains (batch.DASK_MIN_FRAMES), and never
    pays on fewer than DASK_MIN_CORES cores; asking for workers or a scheduler is always Dask."""
    small = [_still(tmp_path / f"s{i}.fap", 98) for i in range(3)]
    big = [_still(tmp_path / f"b{i}.fap", 300) for i in range(3)]
    chosen = batch.choose_runner(small, cores=16)
    assert not chosen.dask and chosen.why.startswith("one after another (294 frames on 16 core(s)")
    assert not batch.choose_runner(big, cores=2).dask
    assert not batch.choose_runner(big[:1], cores=16).dask  # one take: nothing to share out
    assert batch.choose_runner(big, cores=16) == batch.Runner(
        True, 3, "on a local Dask cluster of 3 workers (500+ frames on 16 cores)")
    assert batch.choose_runner(small, cores=16, workers=2) == batch.Runner(
        True, 2, "on a local Dask cluster of 2 worker(s), as asked")
    assert batch.choose_runner(small, scheduler="tcp://h:8786").dask
    assert batch.choose_runner([str(tmp_path / "missing.fap")] * 2, cores=16).why.startswith("one after another (0 ")


def test_puppet_render_of_a_small_batch_says_it_renders_them_in_turn(takes, serial, tmp_path, capsys, egl) -> None:
    from puppet import cli

    _, expected = serial
    out = tmp_path / "videos"
    assert cli.main(["render", *takes, "-o", f"{out}/", "--size", "160x120"]) == 2
    captured = capsys.readouterr()
    said, error = captured.err.splitlines()
    assert said.startswith("rendering 4 takes one after another (122 frames") and "corrupt.fap" in error
    for want in expected:
        if want.ok:
            assert f"{out / Path(want.video).name}: 8 frames sha256 {want.sha256}" in captured.out
