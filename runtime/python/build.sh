#!/usr/bin/env bash
# Builds the release wheel of the `zoo` Python package into target/wheels: one abi3 wheel for
# CPython 3.9+ and Blender's Python (tract compiled in; its only dependency is numpy).
#   bash runtime/python/build.sh            # then: pip install target/wheels/zoo-*.whl
# maturin comes from PATH, else from a virtual environment it makes in target/python-venv.
set -euo pipefail
cd "$(dirname "$0")/../.."
MATURIN=$(command -v maturin || true)
if [ -z "$MATURIN" ]; then
  [ -x target/python-venv/bin/python ] || python3 -m venv target/python-venv
  target/python-venv/bin/python -m pip install -q "maturin>=1.7,<2"
  MATURIN=target/python-venv/bin/maturin
fi
"$MATURIN" build --release -m runtime/python/Cargo.toml -o target/wheels "$@"
