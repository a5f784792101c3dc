"""Every ```python example of docs/python.md and docs/blender.md runs as written.

Each example runs in its own fresh namespace, in a folder holding the files the docs name, made
from the fixtures of `tests/python.rs`: tiny models of each task (`rtn.onnx`, `arnn.onnx`,
`rmr.onnx`, `rnngmm.onnx`) and the synthetic locomotion's clips (`walk.bvh`, `walk2.bvh`).
Examples that `import bpy` need Blender and run in `apps/blender/tests/test_addon.py`."""

import os
import re
import shutil
import textwrap
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[3]
PAGES = ["docs/python.md", "docs/blender.md"]
FILES = {
    "rtn.onnx": "transition.onnx",
    "arnn.onnx": "keyframes.onnx",
    "rmr.onnx": "stitch.onnx",
    "rnngmm.onnx": "synthesis.onnx",
    "walk.bvh": "clip.bvh",
    "walk2.bvh": "clip2.bvh",
}


def examples(page):
    """`(line, code)` of every ```python block of `page`."""
    text = (REPO / page).read_text()
    out = []
    for m in re.finditer(r"^( *)```python\n(.*?)^\1```", text, re.S | re.M):
        out.append((text[: m.start()].count("\n") + 1, textwrap.dedent(m.group(2))))
    return out


CASES = [(page, line, code) for page in PAGES for line, code in examples(page)]


def test_the_pages_have_examples():
    assert len([c for c in CASES if c[0] == "docs/python.md"]) >= 8
    assert any(c[0] == "docs/blender.md" for c in CASES)


@pytest.mark.parametrize("page, line, code", CASES, ids=[f"{p}:{l}" for p, l, _ in CASES])
def test_the_example_runs_as_written(data, tmp_path, page, line, code):
    if re.search(r"^import bpy", code, re.M):
        pytest.skip("a Blender example: run by apps/blender/tests/test_addon.py")
    for name, fixture in FILES.items():
        shutil.copy(data / fixture, tmp_path / name)
    cwd = os.getcwd()
    os.chdir(tmp_path)
    try:
        exec(compile(code, f"{page}:{line}", "exec"), {"__name__": "__doc_example__"})
    finally:
        os.chdir(cwd)
