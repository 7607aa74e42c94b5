"""The ``navkit.io`` package: lazy exports and atomic writes."""

from __future__ import annotations

import numpy as np
import pytest

import navkit.io as nio
from navkit.errors import InputError
from navkit.io import images


@pytest.mark.parametrize("name", nio.__all__)
def test_every_export_resolves(name):
    obj = getattr(nio, name)
    assert obj.__name__ == name


def test_unknown_attribute():
    with pytest.raises(AttributeError, match="no_such_reader"):
        nio.no_such_reader  # noqa: B018


def test_failed_write_leaves_nothing(tmp_path):
    target = tmp_path / "img.xyz"
    with pytest.raises(InputError, match=r"img\.xyz.*suffix"):
        images.write_image(target, np.zeros((2, 2, 3), np.uint8))
    assert list(tmp_path.iterdir()) == []  # neither the target nor a temporary file


def test_failed_write_keeps_old_file(tmp_path):
    target = tmp_path / "img.xyz"
    target.write_bytes(b"old contents")
    with pytest.raises(InputError):
        images.write_image(target, np.zeros((2, 2, 3), np.uint8))
    assert target.read_bytes() == b"old contents"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["img.xyz"]
