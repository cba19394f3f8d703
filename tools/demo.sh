#!/usr/bin/env bash
# One command: set up, then run the main job on the embedded default face.
set -euo pipefail
cd "$(dirname "$0")/.."
bash tools/setup.sh
.venv/bin/puppet demo --out out "$@"
