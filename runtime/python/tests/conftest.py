"""Fixtures of the package's tests: the models, clips and Rust runtime references that
`tests/python.rs` exports into `$ZOO_TEST_DATA` before it runs pytest
(`cargo test -p zoo-tests --test python`)."""

import json
import os
from pathlib import Path

import numpy as np
import pytest


def _data() -> Path:
    d = os.environ.get("ZOO_TEST_DATA")
    if not d:
        pytest.skip("ZOO_TEST_DATA is not set: run the suite through `cargo test -p zoo-tests --test python`")
    return Path(d)


@pytest.fixture(scope="session")
def data() -> Path:
    return _data()


@pytest.fixture(scope="session")
def ref(data):
    """The Rust runtime's outputs for the inputs the tests give the package (`tests/python.rs`)."""
    with open(data / "reference.json") as f:
        return json.load(f)


@pytest.fixture(scope="session")
def clip(data):
    import zoo

    return zoo.read_bvh(data / "clip.bvh")


def arr(values, *shape):
    return np.asarray(values, dtype=np.float64).reshape(shape)
