#!/usr/bin/env bash
# Create .venv (if needed) and install farsighter with its Atari (ALE, MinAtar), envpool, MuJoCo,
# Box2D, exploration, Ray, statistics (rliable), video (moviepy), tracking (wandb) and dev extras
# (the MuJoCo tests need mujoco<3.4 and gymnasium-robotics; they are not skipped).
# torch is installed first and pinned: with no torch present, a range would pull several GB of
# CUDA wheels (SPEC section 5).
set -euo pipefail
cd "$(dirname "$0")/.."
PY=${PYTHON:-python3}
if [ ! -x .venv/bin/python ]; then
  "$PY" -m venv .venv
fi
. .venv/bin/activate
python -m pip install --quiet --upgrade pip
python -m pip install --quiet "torch==2.13.0"
python -m pip install --quiet -e ".[atari,envpool,mujoco,box2d,explore,ray,stats,video,track,dev]"
