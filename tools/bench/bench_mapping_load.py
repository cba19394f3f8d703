"""Seconds to load and check a mapping (best of a few), for the code as it was (``--old-rev``, a
git revision exported to a temporary folder) and as it is, taking turns in fresh processes so a
load that comes and goes on a shared machine hits both alike; prints the medians and the ratio.

    python tools/bench/bench_mapping_load.py [--mapping mappings/arkit_csv.yaml] [--old-rev 9a73db3] [--turns 3]
"""

from __future__ import annotations

import argparse
import io
import statistics
import subprocess
import sys
import tarfile
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
TIMED = """
import sys, time
from puppet.live.mappingfile import load_mapping
load_mapping(sys.argv[1])  # imports and first-use caches out of the way
times = []
for _ in range(5):
    t0 = time.perf_counter()
    load_mapping(sys.argv[1])
    times.append(time.perf_counter() - t0)
print(min(times))
"""


def export(rev: str, folder: Path) -> None:
    """The tree of ``rev`` in ``folder`` (git archive; no checkout touched)."""
    data = subprocess.run(["git", "archive", rev], cwd=ROOT, capture_output=True, check=True).stdout
    with tarfile.open(fileobj=io.BytesIO(data)) as tar:
        tar.extractall(folder, filter="data")


def seconds(root: Path, mapping: Path) -> float:
    run = subprocess.run([sys.executable, "-c", TIMED, str(mapping)], cwd=root, capture_output=True, text=True,
                         env={"PYTHONPATH": str(root), "OPENBLAS_NUM_THREADS": "1"}, check=True)
    return float(run.stdout)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--mapping", type=Path, default=ROOT / "mappings" / "arkit_csv.yaml")
    parser.add_argument("--old-rev", default="9a73db3", help="the revision to compare with (default: before "
                                                             "mappings were composed once, by libyaml)")
    parser.add_argument("--turns", type=int, default=3)
    args = parser.parse_args()
    mapping = args.mapping.resolve()
    with tempfile.TemporaryDirectory() as old:
        export(args.old_rev, Path(old))
        results: dict[str, list[float]] = {"old": [], "new": []}
        for _ in range(args.turns):
            results["old"].append(seconds(Path(old), mapping))
            results["new"].append(seconds(ROOT, mapping))
    old_s, new_s = statistics.median(results["old"]), statistics.median(results["new"])
    print(f"{mapping.name}: old ({args.old_rev}) {old_s * 1000:.0f} ms, new {new_s * 1000:.0f} ms, "
          f"{old_s / new_s:.1f}x (best of 5 loads, median of {args.turns} turns)")


if __name__ == "__main__":
    main()
