#!/usr/bin/env bash
# Set everything up and run the main job: the quick bridge-maze study (paper section 5.1).
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
. .venv/bin/activate
OUT=${OUT:-studies/maze-quick}
farsighter maze --quick --out "$OUT" "$@"
