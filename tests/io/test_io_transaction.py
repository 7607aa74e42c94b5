"""Output transactions: a failed run leaves its output folder exactly as it was."""

from __future__ import annotations

import os

import pytest

from navkit.errors import InputError
from navkit.io.atomic import current_transaction, output_transaction, write_json, write_text


def _snapshot(root):
    return {
        str(p.relative_to(root)): (p.read_bytes() if p.is_file() else None)
        for p in sorted(root.rglob("*"))
    }


def test_commit_keeps_writes_and_leaves_no_backup(tmp_path):
    (tmp_path / "a.txt").write_text("old")
    with output_transaction(tmp_path / "new"):
        write_text(tmp_path / "a.txt", "new")
        write_json(tmp_path / "new" / "b.json", {"x": 1})
        assert (tmp_path / "a.txt").read_text() == "new"  # readable within the run
    assert current_transaction() is None
    assert _snapshot(tmp_path) == {"a.txt": b"new", "new": None, "new/b.json": b'{\n  "x": 1\n}\n'}


@pytest.mark.parametrize("error", [RuntimeError("bug"), KeyboardInterrupt()])
def test_rollback_restores_old_files_and_removes_new_ones(tmp_path, error):
    (tmp_path / "keep").mkdir()
    (tmp_path / "keep" / "a.txt").write_text("old a")
    (tmp_path / "unrelated.txt").write_text("u")
    before = _snapshot(tmp_path)
    with pytest.raises(type(error)), output_transaction(tmp_path / "out"):
        write_text(tmp_path / "keep" / "a.txt", "new a")
        write_text(tmp_path / "keep" / "a.txt", "newer a")  # twice: the first backup wins
        write_text(tmp_path / "out" / "deep" / "b.txt", "b")
        (tmp_path / "out").mkdir(exist_ok=True)
        raise error
    assert _snapshot(tmp_path) == before


def test_nested_transactions_join_the_outer_one(tmp_path):
    with pytest.raises(RuntimeError), output_transaction():
        with output_transaction():
            write_text(tmp_path / "a.txt", "a")
        assert (tmp_path / "a.txt").exists()
        raise RuntimeError
    assert list(tmp_path.iterdir()) == []


def test_output_under_a_file_is_an_input_error(tmp_path):
    (tmp_path / "f").write_text("x")
    with pytest.raises(InputError, match=r"f is a file"):
        write_text(tmp_path / "f" / "sub" / "a.txt", "a")


@pytest.mark.skipif(os.geteuid() == 0, reason="root writes anywhere")
def test_unwritable_folder_is_an_input_error(tmp_path):
    ro = tmp_path / "ro"
    ro.mkdir()
    ro.chmod(0o500)
    try:
        with pytest.raises(InputError, match="not writable"):
            write_text(ro / "a.txt", "a")
    finally:
        ro.chmod(0o700)


def test_rollback_removes_subfolders_the_run_made_itself(tmp_path):
    """A command that makes ``out/frame1`` with mkdir and writes into it, then fails: both go;
    sub-folders that were there before stay, even when empty."""
    out = tmp_path / "out"
    (out / "old-empty").mkdir(parents=True)
    with pytest.raises(RuntimeError), output_transaction(out):
        (out / "frame1" / "deeper").mkdir(parents=True)
        write_text(out / "frame1" / "deeper" / "a.txt", "a")
        raise RuntimeError
    assert sorted(p.name for p in out.iterdir()) == ["old-empty"]
    new = tmp_path / "new-out"
    with pytest.raises(RuntimeError), output_transaction(new):
        (new / "frame1").mkdir(parents=True)
        write_text(new / "frame1" / "a.txt", "a")
        raise RuntimeError
    assert not new.exists()
