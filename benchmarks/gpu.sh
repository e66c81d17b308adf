#!/usr/bin/env bash
# GPU throughput benchmarks in one command, on a Linux machine with an NVIDIA GPU:
#   benchmarks/gpu.sh [CLEANRL_DIR] [extra atari_sps flags...]
# Installs the project (scripts/setup.sh: .venv with torch and the atari + envpool extras), makes
# sure torch is a CUDA build (PyPI's Linux wheel is; a CPU-only one is replaced from
# TORCH_INDEX_URL, default the CUDA 12.8 index), then writes
#   benchmarks/results/update_profile_gpu.json  (one DDQN update: fp32 NCHW, channels-last, bf16)
#   benchmarks/results/atari_sps_gpu.json       (Breakout steps/s, envpool, E = 1 16 32 64; goal 3000)
# CLEANRL_DIR, a CleanRL checkout (cleanrl/dqn_atari.py, cleanrl_utils/), adds its DQN beside.
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/setup.sh
. .venv/bin/activate
if ! python -c 'import sys, torch; sys.exit(not torch.cuda.is_available())'; then
  version=$(python -c 'import torch; print(torch.__version__.split("+")[0])')
  python -m pip install --quiet --force-reinstall --no-deps "torch==$version" \
    --index-url "${TORCH_INDEX_URL:-https://download.pytorch.org/whl/cu128}"
  python -c 'import torch; assert torch.cuda.is_available(), "torch sees no CUDA device"'
fi
python -c 'import torch; print("torch", torch.__version__, "on", torch.cuda.get_device_name(0))'
cleanrl=()
if [ $# -gt 0 ] && [ -d "$1" ]; then
  cleanrl=(--cleanrl "$1")
  shift
fi
python -m benchmarks.update_profile --device cuda
python -m benchmarks.atari_sps --device cuda "${cleanrl[@]}" "$@"
echo "results: benchmarks/results/update_profile_gpu.json benchmarks/results/atari_sps_gpu.json"
