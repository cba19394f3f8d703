"""Ending a child process the show starts (the program window, a headless browser): asked to
stop, then killed when it does not within its grace."""

from __future__ import annotations

import subprocess


def end_process(process: subprocess.Popen, grace: float) -> None:
    """Terminate ``process`` and wait for it; kill it if it has not ended after ``grace`` seconds."""
    if process.poll() is not None:
        return
    process.terminate()
    try:
        process.wait(grace)
    except subprocess.TimeoutExpired:
        process.kill()
        process.wait()
