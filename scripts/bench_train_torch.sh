#!/usr/bin/env bash
# The PyTorch side of `zoo bench train --model rtn`: installs the pinned PyTorch into a virtual
# environment of its own (.venv-bench/, once; about 3 GB with the CUDA libraries that PyPI's
# Linux wheel needs even on CPU) and runs scripts/bench_train_torch.py with the given
# arguments (e.g. `--threads 1,2 --steps 10 --repeats 5`).
set -euo pipefail
cd "$(dirname "$0")/.."
VENV=.venv-bench
if [ ! -x "$VENV/bin/python" ] || ! "$VENV/bin/python" -c 'import torch' 2>/dev/null; then
  python3 -m venv "$VENV"
  "$VENV/bin/pip" install --quiet torch==2.15.0 numpy==2.4.6 >&2
fi
exec "$VENV/bin/python" scripts/bench_train_torch.py "$@"
