#!/usr/bin/env bash
# Set everything up and run the main job; prints where its plots and report are.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
. .venv/bin/activate
OUT=${OUT:-runs/quickstart-cartpole}
farsighter train --algo ddqn --env CartPole-v1 --preset cartpole --total-steps 50000 \
  --run-dir "$OUT" --overwrite
farsighter plot "$OUT"
echo "learning curve: $OUT/learning_curve.png"
