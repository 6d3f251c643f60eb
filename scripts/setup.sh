#!/usr/bin/env bash
# Create .venv and install semattnet with its test tools.
#
# PyTorch: an already installed torch is kept. Otherwise, with an NVIDIA GPU, the default
# (CUDA) wheel from PyPI; without one, the CPU wheel: first a local/mirrored
# torch==$TORCH_VERSION+cpu if pip can see one, else the official CPU index
# ($TORCH_CPU_INDEX). Set TORCH_SPEC to install something else (e.g. TORCH_SPEC="torch==2.4.1").
set -euo pipefail
cd "$(dirname "$0")/.."
PY=${PYTHON:-python3}
VENV=${VENV:-.venv}
TORCH_VERSION=${TORCH_VERSION:-2.13.0}
TORCH_CPU_INDEX=${TORCH_CPU_INDEX:-https://download.pytorch.org/whl/cpu}

[ -x "$VENV/bin/python" ] || "$PY" -m venv "$VENV"
pip() { "$VENV/bin/python" -m pip "$@"; }

if ! "$VENV/bin/python" -c "import torch" 2>/dev/null; then
  if [ -n "${TORCH_SPEC:-}" ]; then
    pip install "$TORCH_SPEC"
  elif command -v nvidia-smi >/dev/null 2>&1 && nvidia-smi -L >/dev/null 2>&1; then
    pip install "torch>=2.1,<3"
  elif ! pip install "torch==${TORCH_VERSION}+cpu" 2>/dev/null; then
    pip install "torch>=2.1,<3" --index-url "$TORCH_CPU_INDEX"
  fi
fi
pip install -q -e ".[dev]"
"$VENV/bin/python" -c "import torch, semattnet; print(f'semattnet {semattnet.__version__} with torch {torch.__version__} (CUDA: {torch.cuda.is_available()})')"
