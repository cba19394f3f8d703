#!/usr/bin/env bash
# One command: set up, then lint (ruff), type-check (mypy) and run the test suite; any failure fails it.
set -euo pipefail
cd "$(dirname "$0")/.."
bash tools/setup.sh
"${VENV:-.venv}/bin/python" -m ruff check .
"${VENV:-.venv}/bin/python" -m mypy
"${VENV:-.venv}/bin/python" -m pytest -q "$@"
