"""Write output files atomically: a reader never sees a half-written file.

Data go to a temporary file in the same folder, which replaces the target only when the write
succeeded; on any error the temporary file is removed and the old target (if any) is untouched.

Output transactions
-------------------
One file at a time is not enough for a command that writes several files and then meets a bad
input: :func:`output_transaction` makes a whole run all-or-nothing. While a transaction is open
(the CLI opens one around every command, :func:`navkit.cli.common.cli_errors`), each committed
write is recorded: a file that existed before the transaction is kept as a hidden backup (a hard
link, or a copy where links are not possible) beside it, a new file is remembered, and so is
every folder the writes created. When the block succeeds the backups are deleted; when it fails
(any exception, Ctrl-C included) new files and new folders are removed and the backups are put
back, so ``--out`` is exactly as it was. Files are renamed into place as they are written, so a
command can read back its own outputs within the run.
"""

from __future__ import annotations

import contextvars
import json
import logging
import os
import shutil
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, Any

import numpy as np

__all__ = [
    "OutputTransaction",
    "atomic_path",
    "atomic_write",
    "output_transaction",
    "read_json",
    "settings_to_toml",
    "to_jsonable",
    "write_json",
    "write_run_files",
    "write_text",
]

log = logging.getLogger(__name__)


@dataclass
class OutputTransaction:
    """What the writes of one run changed, so that a failed run can be undone.

    Attributes
    ----------
    backups : dict of Path to Path or None
        For each target written, the hidden backup of its previous contents (None: new file).
    created_dirs : list of Path
        Folders that did not exist before and were created by the writes (or by
        :meth:`watch_dir`), in creation order.
    """

    backups: dict[Path, Path | None] = field(default_factory=dict)
    created_dirs: list[Path] = field(default_factory=list)
    roots: dict[Path, set[Path]] = field(default_factory=dict)
    # created_dirs as a set: a long run watches one new folder per frame
    _created: set[Path] = field(default_factory=set, repr=False)

    def watch_root(self, folder: str | os.PathLike[str]) -> None:
        """Watch an output folder: a rollback also removes the empty sub-folders it did not have
        (ones a command made itself with ``mkdir``, not through the atomic writers)."""
        root = Path(folder).absolute()
        if root in self.roots:
            return
        existing: set[Path] = set()
        if root.is_dir():
            existing = {Path(sub) for sub, _, _ in os.walk(root)}
        self.roots[root] = existing
        self.watch_dir(root)

    def watch_dir(self, folder: str | os.PathLike[str]) -> None:
        """Remember the missing ancestors of ``folder`` so a rollback removes them if empty."""
        missing = []
        d = Path(folder).absolute()
        while not d.exists() and d != d.parent:
            missing.append(d)
            d = d.parent
        for d in reversed(missing):
            if d not in self._created:
                self._created.add(d)
                self.created_dirs.append(d)

    def before_replace(self, target: Path) -> None:
        """Back up ``target``'s current contents (once per transaction) before it is replaced."""
        target = target.absolute()
        if target in self.backups:
            return
        if not target.exists():
            self.backups[target] = None
            return
        fd, name = tempfile.mkstemp(dir=target.parent, prefix=f".{target.name}.", suffix=".bak")
        os.close(fd)
        backup = Path(name)
        backup.unlink()
        try:
            os.link(target, backup)
        except OSError:
            shutil.copy2(target, backup)
        self.backups[target] = backup

    def commit(self) -> None:
        """Keep every write: delete the backups."""
        for backup in self.backups.values():
            if backup is not None:
                backup.unlink(missing_ok=True)
        self.backups.clear()
        self.created_dirs.clear()
        self._created.clear()
        self.roots.clear()

    def rollback(self) -> None:
        """Undo every write: remove new files and folders, put the old files back."""
        for target, backup in reversed(list(self.backups.items())):
            try:
                if backup is None:
                    target.unlink(missing_ok=True)
                else:
                    os.replace(backup, target)
            except OSError as exc:  # pragma: no cover - best effort, never mask the real error
                log.warning("could not restore %s: %s", target, exc)
        for root, existing in self.roots.items():
            if not root.is_dir():
                continue
            for sub, _, _ in os.walk(root, topdown=False):
                if Path(sub) not in existing and Path(sub) != root:
                    try:
                        os.rmdir(sub)  # only when empty: files the run did not write stay
                    except OSError:
                        pass
        for d in reversed(self.created_dirs):
            try:
                d.rmdir()  # only when empty: files the run did not write stay
            except OSError:
                pass
        self.backups.clear()
        self.created_dirs.clear()
        self._created.clear()
        self.roots.clear()


_TRANSACTION: contextvars.ContextVar[OutputTransaction | None] = contextvars.ContextVar(
    "navkit_output_transaction", default=None
)


def current_transaction() -> OutputTransaction | None:
    """The open :class:`OutputTransaction`, or None outside :func:`output_transaction`."""
    return _TRANSACTION.get()


@contextmanager
def output_transaction(*watch: str | os.PathLike[str] | None) -> Iterator[OutputTransaction]:
    """Make every atomic write inside the block all-or-nothing (see the module docstring).

    Parameters
    ----------
    *watch : path, optional
        Output folders (``--out``): a rollback removes the folders and sub-folders the block
        created in them (with the writers or its own ``mkdir``) when they are left empty.
        Folders created by the writes are tracked anywhere.

    Nested transactions join the outer one (only the outermost commits or rolls back).
    """
    outer = _TRANSACTION.get()
    if outer is not None:
        for folder in watch:
            if folder is not None:
                outer.watch_root(folder)
        yield outer
        return
    txn = OutputTransaction()
    for folder in watch:
        if folder is not None:
            txn.watch_root(folder)
    token = _TRANSACTION.set(txn)
    try:
        yield txn
    except BaseException:
        txn.rollback()
        raise
    else:
        txn.commit()
    finally:
        _TRANSACTION.reset(token)


def _make_parent(target: Path) -> None:
    """Create ``target``'s folder; a path under a file or an unwritable folder is an InputError."""
    from navkit.errors import InputError

    parent = target.parent
    for d in (parent, *parent.parents):
        if d.exists():
            if not d.is_dir():
                raise InputError(
                    f"{d} is a file, not a folder",
                    source=target,
                    field="output folder",
                    expected="a folder (or a path that does not exist yet)",
                )
            break
    try:
        parent.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise InputError(
            f"cannot create the folder: {exc.strerror}",
            source=parent,
            field="output folder",
            expected="a writable folder",
        ) from None
    if not os.access(parent, os.W_OK | os.X_OK):
        raise InputError(
            "the folder is not writable",
            source=parent,
            field="output folder",
            expected="a writable folder",
        )


@contextmanager
def atomic_path(path: str | os.PathLike[str]) -> Iterator[Path]:
    """Yield a temporary path beside ``path``; it replaces ``path`` when the block succeeds.

    The temporary name keeps the target's suffix, so writers that pick a format by extension
    (OpenCV's ``imwrite``, matplotlib's ``savefig``) still work.
    """
    target = Path(path)
    txn = _TRANSACTION.get()
    if txn is not None:
        txn.watch_dir(target.parent)
    _make_parent(target)
    fd, tmp = tempfile.mkstemp(dir=target.parent, prefix=f".{target.name}.", suffix=target.suffix)
    os.close(fd)
    umask = os.umask(0)
    os.umask(umask)
    os.chmod(tmp, 0o666 & ~umask)  # mkstemp makes 0600; outputs get the usual permissions
    try:
        yield Path(tmp)
        if txn is not None:
            txn.before_replace(target)
        os.replace(tmp, target)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


@contextmanager
def atomic_write(path: str | os.PathLike[str], mode: str = "w") -> Iterator[IO[Any]]:
    """Open a temporary file for writing (``"w"`` text, ``"wb"`` binary); commit on success."""
    with atomic_path(path) as tmp, open(tmp, mode, encoding=None if "b" in mode else "utf-8") as fh:
        yield fh


def to_jsonable(obj: Any) -> Any:
    """Convert NumPy scalars/arrays, paths and dataclasses to plain JSON types (NaN -> None)."""
    import dataclasses

    if dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        return {f.name: to_jsonable(getattr(obj, f.name)) for f in dataclasses.fields(obj)}
    if isinstance(obj, dict):
        return {str(k): to_jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [to_jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return to_jsonable(obj.tolist())
    if isinstance(obj, np.generic):
        return to_jsonable(obj.item())
    if isinstance(obj, float):
        return obj if np.isfinite(obj) else None
    if isinstance(obj, Path):
        return str(obj)
    return obj


def write_json(path: str | os.PathLike[str], data: Any, indent: int = 2) -> None:
    """Write ``data`` as JSON atomically (NumPy types converted, NaN written as null)."""
    with atomic_write(path) as fh:
        json.dump(to_jsonable(data), fh, indent=indent, allow_nan=False)
        fh.write("\n")


def write_text(path: str | os.PathLike[str], text: str) -> None:
    """Write text atomically."""
    with atomic_write(path) as fh:
        fh.write(text)


def read_json(path: str | os.PathLike[str], *, what: str = "a JSON file") -> Any:
    """Read a JSON file (the one JSON reader of navkit; size-bounded, UTF-8, nesting-safe:
    :func:`navkit.io.textfiles.load_json_file`).

    Raises
    ------
    DataNotFoundError
        The file does not exist.
    FormatError
        It is not UTF-8 JSON, too large or nested too deeply (the message names the file and
        ``what`` was expected).
    """
    from navkit.io.textfiles import load_json_file

    return load_json_file(path, what)


def settings_to_toml(settings: Any) -> str:
    """Settings (dataclasses, dicts, arrays) as TOML text; TOML has no null, so None values are
    left out."""
    import tomli_w

    def clean(value: Any) -> Any:
        if isinstance(value, dict):
            return {k: clean(v) for k, v in value.items() if v is not None}
        if isinstance(value, list):
            return [clean(v) for v in value if v is not None]
        return value

    return tomli_w.dumps(clean(to_jsonable(settings)))


def write_run_files(
    out: str | os.PathLike[str],
    settings: Any,
    summary: dict[str, Any],
    *,
    reference: str | None = None,
) -> None:
    """Write ``settings.toml`` (the resolved settings; TOML has no null, so None values are left
    out) and ``summary.json`` (with the navkit version, the command line and which
    implementation of the hot paths ran, :func:`navkit.jit.implementation`) into ``out``
    atomically: what every navkit run writes next to its outputs.

    Parameters
    ----------
    reference : str, optional
        What the summary's headline figures (errors, success rates, scores) are measured
        against, written as the ``"reference"`` field right after the version and the command
        line - e.g. ``"simulator ground truth"``, ``"SemanticKITTI labels"``, or, for a map
        located with the same log it was built from, ``"self-consistency: the map was built from
        this log's poses; not an accuracy figure"``. A ``"reference"`` key in ``summary`` is
        taken when the keyword is not given.
    """
    import sys

    from navkit import __version__
    from navkit.jit import implementation

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    write_text(out / "settings.toml", settings_to_toml(settings))
    head: dict[str, Any] = {"navkit_version": __version__, "argv": sys.argv[1:]}
    ref = reference if reference is not None else summary.get("reference")
    if ref is not None:
        head["reference"] = ref
    head["kernels"] = implementation()  # timings of a first run on a fresh machine: NumPy twins
    write_json(
        out / "summary.json", {**head, **{k: v for k, v in summary.items() if k != "reference"}}
    )
