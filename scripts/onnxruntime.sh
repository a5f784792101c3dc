#!/usr/bin/env bash
# Provisions the onnxruntime shared library that the parity tests load through `ort`
# (feature `load-dynamic`): downloads the onnxruntime 1.31.1 wheel from PyPI, extracts
# libonnxruntime.so.1.31.1 into <workspace>/.onnxruntime/ (gitignored) and prints its path.
# Then: export ORT_DYLIB_PATH=<printed path>   (the tests default to that path anyway).
# Also installs the onnxruntime Python package and numpy into <workspace>/.onnxruntime/venv.
set -euo pipefail
cd "$(dirname "$0")/.."
VERSION=1.31.1
DIR=.onnxruntime
LIB="$DIR/libonnxruntime.so.$VERSION"
if [ ! -f "$LIB" ]; then
    mkdir -p "$DIR/wheel"
    PIP="pip"
    command -v pip >/dev/null 2>&1 || PIP="python3 -m pip"
    $PIP download --no-deps --only-binary=:all: "onnxruntime==$VERSION" -d "$DIR/wheel" >&2
    WHEEL=$(ls "$DIR"/wheel/onnxruntime-"$VERSION"-*.whl | head -n 1)
    python3 - "$WHEEL" "$LIB" "$VERSION" <<'PY'
import sys, zipfile, shutil
wheel, out, version = sys.argv[1:]
with zipfile.ZipFile(wheel) as z, z.open(f"onnxruntime/capi/libonnxruntime.so.{version}") as src, open(out, "wb") as dst:
    shutil.copyfileobj(src, dst)
PY
    rm -rf "$DIR/wheel"
fi
# The Python side of tests/protocol.rs (an independent implementation of
# docs/runtime-protocol.md): the same onnxruntime as a Python package, with numpy, in a venv.
VENV="$DIR/venv"
if ! "$VENV/bin/python" -c 'import onnxruntime, numpy' 2>/dev/null; then
    python3 -m venv "$VENV" >&2
    "$VENV/bin/pip" install --quiet --disable-pip-version-check "onnxruntime==$VERSION" "numpy==2.4.6" >&2
fi
realpath "$LIB"
