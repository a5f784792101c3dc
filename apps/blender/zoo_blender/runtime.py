"""The `zoo` Python package inside Blender, and the models loaded with it.

`zoo` is imported as installed (pip into Blender's Python, or by Blender 4.2+ from the
extension's `wheels/`); otherwise from the wheel bundled in the add-on's `wheels/` folder,
extracted once into `_vendor/` beside it (a compiled extension cannot be imported from inside a
zip)."""

import os
import sys
import zipfile
from pathlib import Path

HERE = Path(__file__).resolve().parent


class Refusal(Exception):
    """An operation refused before anything changed; the message is for the status bar."""


def _vendored():
    wheels = sorted((HERE / "wheels").glob("zoo-*.whl"))
    if not wheels:
        return None
    wheel = wheels[-1]
    vendor = HERE / "_vendor"
    marker = vendor / ".wheel"
    if not (marker.is_file() and marker.read_text() == wheel.name):
        vendor.mkdir(exist_ok=True)
        with zipfile.ZipFile(wheel) as z:
            z.extractall(vendor)
        marker.write_text(wheel.name)
    return str(vendor)


def zoo():
    """The `zoo` module, or a `Refusal` saying how to install it."""
    try:
        import zoo as module

        return module
    except ImportError:
        pass
    path = _vendored()
    if path is not None and path not in sys.path:
        sys.path.insert(0, path)
    try:
        import zoo as module

        return module
    except ImportError as e:
        raise Refusal(
            f"the zoo Python package is not installed in Blender's Python ({e}): install the add-on zip made by "
            "apps/blender/make_addon.py (it carries the wheel), or pip install the wheel into Blender's Python"
        ) from None


_MODELS = {}


def load_model(path):
    """The model file at `path` (a Blender path, `//` relative to the .blend), loaded once per
    modification time."""
    import bpy

    if not path:
        raise Refusal("no model file: choose an exported model (.onnx) in the zoo panel")
    full = os.path.abspath(bpy.path.abspath(path))
    if not os.path.isfile(full):
        raise Refusal(f"model file {full} does not exist")
    mtime = os.path.getmtime(full)
    cached = _MODELS.get(full)
    if cached and cached[0] == mtime:
        return cached[1]
    z = zoo()
    try:
        model = z.load(full)
    except z.ZooError as e:
        raise Refusal(f"cannot load {os.path.basename(full)}: {e}") from None
    _MODELS[full] = (mtime, model)
    return model


def model_of_task(path, tasks, operation):
    """The model at `path`, refused unless its task is one of `tasks`."""
    m = load_model(path)
    if m.task not in tasks:
        wanted = " or ".join(f"a {t}" for t in tasks)
        raise Refusal(
            f"{operation} needs {wanted} model; {os.path.basename(m.path)} is a {m.task} model ({m.kind}): "
            f"choose another model file"
        )
    return m
