"""Run the fuzz properties for longer than CI does and print the counts a robustness report needs.

The properties are the test suite's own (``tests/test_fuzz_inputs.py``: .fap files, mappings,
serial framing, OSC datagrams, the control API's messages and OSC control addresses, take
folders; ``tests/test_hid_descriptors.py``: HID descriptors), run by pytest exactly as CI runs
them, with ``PUPPET_FUZZ_SCALE`` raised so that each target takes about its share of the budget
(a first run at scale 1 measures it). For each kind of input
it prints the inputs tried, how many were read, how many were refused with a documented error,
anything else (an undocumented exception or a memory peak past the bound: must be 0) and the
slowest input; a property that fails (anything else, or an input past hypothesis's deadline)
is named with pytest's one-line reason, and the exit code is 1::

    python tools/checks/fuzz.py --minutes 15
    python tools/checks/fuzz.py --minutes 2 --only mapping,osc
"""

from __future__ import annotations

import argparse
import ast
import os
import re
import subprocess
import sys
import time
from collections import Counter
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
TARGETS = {
    "fap-bytes": "tests/test_fuzz_inputs.py::test_arbitrary_bytes_as_a_fap_file",
    "fap-near-valid": "tests/test_fuzz_inputs.py::test_near_valid_fap_files",
    "mapping": "tests/test_fuzz_inputs.py::test_mapping_text",
    "serial": "tests/test_fuzz_inputs.py::test_serial_framing",
    "osc": "tests/test_fuzz_inputs.py::test_osc_datagrams",
    "api": "tests/test_fuzz_inputs.py::test_api_messages",
    "osc-control": "tests/test_fuzz_inputs.py::test_osc_control_messages",
    "take-folders": "tests/test_fuzz_inputs.py::test_garbled_take_folders",
    "hid": "tests/test_hid_descriptors.py::test_any_bytes_as_a_descriptor_read_or_refused_in_bounded_memory",
}


def run(node: str, scale: int) -> tuple[float, float, bool, str, Counter, dict[str, float]]:
    """One pytest run of one property: seconds in all and in the property itself, passed, the
    failure line, the tally, the slowest input in ms by kind."""
    start = time.perf_counter()
    out = subprocess.run([sys.executable, "-m", "pytest", "-q", "-s", "-p", "no:cacheprovider", "-o", "addopts=",
                          "--durations=1", "--durations-min=0", node], cwd=ROOT, capture_output=True, text=True,
                         env={**os.environ, "PUPPET_FUZZ_SCALE": str(scale), "PYTHONPATH": str(ROOT)})
    seconds = time.perf_counter() - start
    tally, slowest, call = Counter(), {}, seconds
    for line in out.stdout.splitlines():
        if re.match(r"[0-9.]+s call ", line):
            call = float(line.split("s", 1)[0])
        elif line.startswith("fuzz tally: "):
            tally.update(ast.literal_eval(line[len("fuzz tally: "):]))
        elif line.startswith("fuzz slowest ms: "):
            slowest.update(ast.literal_eval(line[len("fuzz slowest ms: "):]))
    failure = next((line for line in out.stdout.splitlines() if line.startswith(("FAILED", "ERROR"))), "")
    return seconds, call, out.returncode == 0, failure, tally, slowest


def rows(tally: Counter, slowest: dict[str, float]) -> list[tuple]:
    kinds = sorted({key.rsplit(": ", 1)[0] for key in tally})
    out = []
    for kind in kinds:
        read, documented = tally[f"{kind}: read"], tally[f"{kind}: documented error"]
        other = tally[f"{kind}: other"] + tally[f"{kind}: over the memory bound"]
        out.append((kind, read + documented + tally[f"{kind}: other"], read, documented, other,
                    tally[f"{kind}: bad frames skipped"], slowest.get(kind, float("nan"))))
    return out


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--minutes", type=float, default=10.0, help="the whole budget, shared by the targets")
    parser.add_argument("--only", default="", help=f"comma-separated targets among {', '.join(TARGETS)}")
    args = parser.parse_args()
    chosen = [t for t in args.only.split(",") if t] or list(TARGETS)
    unknown = [t for t in chosen if t not in TARGETS]
    if unknown:
        parser.error(f"unknown target {unknown[0]!r}: expected one of {', '.join(TARGETS)}")
    share = 60 * args.minutes / len(chosen)
    table, failures = [], []
    for target in chosen:
        seconds, call, passed, failure, tally, slowest = run(TARGETS[target], 1)
        scale = int((share - 2 * seconds + call) / max(call, 0.1))  # the next run starts up again
        if passed and scale >= 1:
            more = run(TARGETS[target], scale)
            seconds, passed, failure = seconds + more[0], more[2], more[3]
            tally.update(more[4])
            slowest = {k: max(slowest.get(k, 0.0), more[5].get(k, 0.0)) for k in {**slowest, **more[5]}}
        print(f"{target}: {seconds:.0f} s, {'passed' if passed else 'FAILED'}", file=sys.stderr, flush=True)
        if not passed:
            failures.append(f"{target}: {failure or 'pytest failed'}")
        table += rows(tally, slowest)
    print(f"{'input kind':<18} {'tried':>9} {'read':>9} {'documented error':>17} {'anything else':>14} "
          f"{'bad frames skipped':>19} {'slowest ms':>11}")
    for kind, tried, read, documented, other, skipped, ms in table:
        print(f"{kind:<18} {tried:>9,} {read:>9,} {documented:>17,} {other:>14,} {skipped:>19,} {ms:>11.1f}")
    totals = [sum(row[i] for row in table) for i in (1, 2, 3, 4, 5)]
    print(f"{'all':<18} {totals[0]:>9,} {totals[1]:>9,} {totals[2]:>17,} {totals[3]:>14,} {totals[4]:>19,}")
    for line in failures:
        print(re.sub(r"\s+", " ", line))
    return 1 if failures or totals[3] else 0


if __name__ == "__main__":
    sys.exit(main())
