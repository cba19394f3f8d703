"""Print the figures that say how readable the house is: modules per folder, the longest
functions, and what importing a module costs (time, and whether it drags in moderngl).

    .venv/bin/python tools/checks/house_figures.py [--repo DIR] [MODULE ...]

``--repo`` measures another checkout (e.g. an older commit in a worktree) the same way, so a
before and after come from one command. Import times are the median of five fresh interpreters
(``python -X importtime``, the module's cumulative time).
"""

from __future__ import annotations

import argparse
import ast
import statistics
import subprocess
import sys
from collections import Counter
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def module_counts(repo: Path) -> Counter:
    """Python modules per folder of ``puppet/`` and ``devices/``."""
    return Counter(str(p.parent.relative_to(repo)) for p in _modules(repo))


def longest_functions(repo: Path, most: int = 5) -> list[tuple[int, str]]:
    """The ``most`` longest functions as (lines, 'path:name'), longest first."""
    lengths = []
    for path in _modules(repo):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                lengths.append((node.end_lineno - node.lineno + 1, f"{path.relative_to(repo)}:{node.name}"))
    return sorted(lengths, reverse=True)[:most]


def import_cost(repo: Path, module: str, runs: int = 5) -> tuple[float, bool]:
    """(median seconds to import ``module`` in a fresh interpreter, whether moderngl got loaded)."""
    seconds = []
    for _ in range(runs):
        report = subprocess.run([sys.executable, "-X", "importtime", "-c", f"import {module}"], cwd=repo,
                                capture_output=True, text=True, check=True).stderr.strip().splitlines()
        seconds.append(int(report[-1].split("|")[1]) / 1e6)
    loaded = subprocess.run([sys.executable, "-c", f"import sys, {module}; print('moderngl' in sys.modules)"],
                            cwd=repo, capture_output=True, text=True, check=True).stdout.strip() == "True"
    return statistics.median(seconds), loaded


def _modules(repo: Path) -> list[Path]:
    return sorted([*repo.glob("puppet/**/*.py"), *repo.glob("devices/**/*.py")])


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repo", type=Path, default=ROOT, help="the checkout to measure (default: this one)")
    parser.add_argument("modules", nargs="*", default=["puppet", "puppet.io", "puppet.live.mappingfile"])
    args = parser.parse_args(argv)
    for folder, n in sorted(module_counts(args.repo).items()):
        print(f"{folder}: {n} modules")
    for lines, where in longest_functions(args.repo):
        print(f"{lines:4d} lines  {where}")
    for module in args.modules:
        seconds, loaded = import_cost(args.repo, module)
        print(f"import {module}: {seconds:.3f} s (median of 5), moderngl {'loaded' if loaded else 'not loaded'}")


if __name__ == "__main__":
    main()
