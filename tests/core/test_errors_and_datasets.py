"""The error hierarchy's messages, the data finder, and the atomic writers."""

import json
from pathlib import Path

import numpy as np
import pytest

import navkit
from navkit import datasets
from navkit.errors import (
    DataNotFoundError,
    FormatError,
    InputError,
    NavkitError,
    OptionalDependencyError,
    require_module,
)
from navkit.io.atomic import atomic_path, write_json


def test_input_error_names_source_field_and_expectation():
    err = FormatError(
        "truncated", source="a/b.bin", field="points", expected="a multiple of 16 bytes"
    )
    assert str(err) == "a/b.bin: field 'points': truncated (expected a multiple of 16 bytes)"
    assert (
        isinstance(err, InputError) and isinstance(err, NavkitError) and isinstance(err, ValueError)
    )


def test_public_api():
    assert navkit.__version__.count(".") == 2
    assert issubclass(navkit.DegenerateGeometryError, navkit.NavkitError)


def test_require_module_hint():
    with pytest.raises(OptionalDependencyError, match=r"pip install 'navkit\[bench\]'"):
        require_module("surely_not_a_module_xyz", "bench", "a comparison")


def test_datasets_env_var(tmp_path, monkeypatch):
    (tmp_path / "lidar").mkdir()
    monkeypatch.setenv("NAVKIT_DATA", str(tmp_path))
    assert datasets.find("lidar") == (tmp_path / "lidar").resolve()
    with pytest.raises(DataNotFoundError, match="nothing"):
        datasets.find("nothing")
    monkeypatch.setenv("NAVKIT_DATA", str(tmp_path / "absent"))
    with pytest.raises(DataNotFoundError, match="NAVKIT_DATA"):
        datasets.data_root()


def test_atomic_write_leaves_nothing_on_failure(tmp_path):
    target = tmp_path / "out.json"
    target.write_text("old")
    with pytest.raises(RuntimeError), atomic_path(target) as tmp:
        Path(tmp).write_text("half")
        raise RuntimeError("boom")
    assert target.read_text() == "old"
    assert list(tmp_path.iterdir()) == [target]


def test_write_json_numpy_and_nan(tmp_path):
    write_json(tmp_path / "s.json", {"a": np.float32(1.5), "b": np.arange(3), "c": float("nan")})
    assert json.loads((tmp_path / "s.json").read_text()) == {"a": 1.5, "b": [0, 1, 2], "c": None}
