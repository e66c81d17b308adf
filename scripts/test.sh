#!/usr/bin/env bash
# Set everything up and run lint, type checks and the default (fast) test suite.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
. .venv/bin/activate
ruff check farsighter tests benchmarks
mypy
python -m pytest -n 2 -q "$@"
