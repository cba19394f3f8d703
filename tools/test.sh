#!/usr/bin/env bash
# One command: set up, then run the test suite.
set -euo pipefail
cd "$(dirname "$0")/.."
bash tools/setup.sh
"${VENV:-.venv}/bin/python" -m pytest -q "$@"
