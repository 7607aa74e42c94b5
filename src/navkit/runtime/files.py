"""Per-frame files written off the run's hot path: a writer process with a bounded queue.

The loop hands each frame's files (e.g. the obstacles' ``labels.npy`` + ``obstacles.json``) to
:class:`FileWriter` as plain data (arrays, dicts of numbers and names: pickled in about 0.2 ms
for a KITTI frame); a separate process encodes and writes them, while the loop goes on with the
next message. Decision: a process, not a thread: encoding a KITTI frame's ``obstacles.json``
(~150 kB) holds Python's GIL for 7-14 ms, which a writer thread takes from the loop's thread
(the compiled kernels hold the GIL too), so the loop would pay it all the same.

- Each file is written atomically (a temporary file beside it, then renamed). The loop, not the
  writer, records the file in the caller's output transaction
  (:func:`navkit.io.atomic.output_transaction`) before queueing it, so a failed command still
  removes it.
- At most ``maxsize`` jobs (a job: one frame's files) are queued: a loop faster than the disk
  waits (memory stays bounded). A writer process that dies is an error at the next wait, never a hang.
- :meth:`FileWriter.drain` waits until every queued file is written and raises the first error
  (:class:`~navkit.errors.InputError` naming the file); the run drains before every checkpoint
  and at the end, so a checkpoint never counts a file that is not on disk.
- A run takes its writer with :func:`acquire_writer` and hands it back, drained, with
  :func:`release_writer`; the process keeps one idle writer for the next run. Decision: the
  writer is forked, and after a fork every page the two processes share is copied the first
  time the loop writes to it (the detector's buffers, the interpreter's objects: about 20 000
  page copies, ~50 ms of the loop's CPU); a writer kept between runs pays that once per
  process, not once per run.
"""

from __future__ import annotations

import io
import json
import multiprocessing as mp
import os
import re
import tempfile
import threading
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["FileWriter", "acquire_writer", "dumps_json", "idle_writer_pid", "release_writer"]

_NONFINITE = re.compile(r"(?<=[\[,:\s])(?:-?Infinity|NaN)(?=[\],}\s])")


def _default(o: Any) -> Any:
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, np.generic):
        return o.item()
    if isinstance(o, Path):
        return str(o)
    raise TypeError(f"{type(o).__name__} is not JSON serialisable")


def dumps_json(data: Any, indent: int | None = None) -> str:
    """JSON of plain data with NumPy arrays / scalars, NaN and infinities written as ``null``
    (as :func:`navkit.io.atomic.write_json`), by the C encoder (``indent=None``): about 3x
    faster than converting the tree in Python first. The values are numbers and navkit's own
    names, so a bare ``NaN`` / ``Infinity`` token is always a number."""
    try:  # most documents have no NaN / infinity: no pass of the regular expression
        return json.dumps(data, default=_default, indent=indent, allow_nan=False)
    except ValueError:
        text = json.dumps(data, default=_default, indent=indent, allow_nan=True)
        return _NONFINITE.sub("null", text)


def encode(kind: str, payload: Any) -> bytes:
    """A file's bytes: ``"json"`` (:func:`dumps_json` + newline), ``"npy"`` (``np.save``) or
    ``"obstacles"`` (``obstacles.json``: ``payload`` is the document without its
    ``"obstacles"``, and the obstacles' :meth:`~navkit.obstacles.Obstacle.json_fields` under
    ``"obstacle_fields"``; each made into :meth:`~navkit.obstacles.Obstacle.to_dict`'s dict
    here, in the writer)."""
    if kind == "obstacles":
        from navkit.obstacles.detector import obstacle_dict

        doc = dict(payload)
        doc["obstacles"] = [obstacle_dict(*f) for f in doc.pop("obstacle_fields")]
        kind, payload = "json", doc
    if kind == "json":
        return (dumps_json(payload) + "\n").encode()
    buf = io.BytesIO()
    np.save(buf, payload)
    return buf.getvalue()


def _write_atomic(path: str, data: bytes) -> None:
    target = Path(path)
    target.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=target.parent, prefix=f".{target.name}.", suffix=target.suffix)
    try:
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)
        os.replace(tmp, target)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def _serve(jobs: Any, done: Any) -> None:
    """The writer process: jobs (tuples of ``(kind, path, payload)`` files) until ``None``; one
    ``(path, error or None)`` reply per job (its first failed file, or its last file). It
    ignores SIGINT: Ctrl-C in a terminal reaches the whole process group, and the run, not its
    writer, decides how to stop (it drains the writer first)."""
    import signal

    signal.signal(signal.SIGINT, signal.SIG_IGN)
    while True:
        job = jobs.get()
        if job is None:
            return
        reply: tuple[str, str | None] = ("", None)
        for kind, path, payload in job:
            try:
                _write_atomic(path, encode(kind, payload))
                reply = (path, None)
            except Exception as exc:
                reply = (path, f"{type(exc).__name__}: {exc}")
                break
        done.put(reply)


class FileWriter:
    """A writer process for per-frame files (see the module docstring)."""

    def __init__(self, maxsize: int = 8) -> None:
        # fork: "spawn" and "forkserver" re-import the caller's main module in the child, which
        # re-runs an unguarded script (``python myscript.py`` calling run_recording); the forked
        # child only encodes JSON / NumPy and writes files, touching none of the parent's threads
        methods = mp.get_all_start_methods()
        ctx = mp.get_context("fork" if "fork" in methods else "spawn")
        self.maxsize = maxsize
        self._jobs = ctx.Queue()
        self._done = ctx.Queue()
        self._pending = 0
        self._error: tuple[str, str] | None = None
        self._proc = ctx.Process(  # type: ignore[attr-defined]
            target=_serve, args=(self._jobs, self._done), name="navkit-files", daemon=True
        )
        self._pid = os.getpid()  # the process that started the writer (its only user)
        self._proc.start()

    def submit_files(self, files: list[tuple[str, Path, Any]]) -> None:
        """Queue files (``(kind of`` :func:`encode` ``, path, payload)``) written one after the
        other as one job (e.g. a frame's files); waits while ``maxsize`` jobs are queued. The
        files (and their folders) are recorded in the caller's output transaction here; the
        writer creates the folders."""
        from navkit.io.atomic import current_transaction

        job = tuple((kind, str(path), payload) for kind, path, payload in files)
        txn = current_transaction()
        if txn is not None:
            for _, path, _ in files:
                path = Path(path)
                txn.watch_dir(path.parent)
                txn.before_replace(path)
        while self._pending >= self.maxsize:
            self._wait_one()
        self._jobs.put(job)
        self._pending += 1

    def _wait_one(self) -> None:
        """Take one reply; a writer that died is an error, never a wait forever."""
        import queue

        while True:
            try:
                path, err = self._done.get(timeout=1.0)
                break
            except queue.Empty:
                if not self._proc.is_alive():
                    self._pending = 0
                    self._raise(f"the writer process ended (exit code {self._proc.exitcode})")
        self._pending -= 1
        if err is not None and self._error is None:
            self._error = (path, err)

    def _raise(self, reason: str, path: Any = None) -> None:
        from navkit.errors import InputError

        raise InputError(
            f"could not be written: {reason}",
            source=path or "per-frame files",
            expected="a writable output folder",
        )

    def usable(self) -> bool:
        """Whether this process started the writer and it is still running."""
        return self._pid == os.getpid() and self._proc.is_alive()

    def drain(self) -> None:
        """Wait until every queued file is written; raise the first error one hit."""
        while self._pending:
            self._wait_one()
        if self._error is not None:
            (path, reason), self._error = self._error, None
            self._raise(reason, path)

    def close(self) -> None:
        """Drain and stop the process."""
        try:
            self.drain()
        finally:
            if self._proc.is_alive():
                self._jobs.put(None)
                self._proc.join(timeout=30)
            if self._proc.is_alive():
                self._proc.terminate()


_idle: list[FileWriter] = []  # at most one writer kept between runs
_idle_lock = threading.Lock()


def acquire_writer() -> FileWriter:
    """A writer for one user until :func:`release_writer`: the idle one kept from an earlier
    user when this process started it and it still runs, else a new one."""
    with _idle_lock:
        while _idle:
            w = _idle.pop()
            if w.usable():
                return w
    return FileWriter()


def release_writer(w: FileWriter) -> None:
    """Wait until ``w`` has written everything (raising its first error, as
    :meth:`FileWriter.drain`) and keep it for the next user; a writer that failed, or one more
    than the one kept, is closed."""
    try:
        w.drain()
    except BaseException:
        w.close()
        raise
    with _idle_lock:
        if not _idle and w.usable():
            _idle.append(w)
            return
    w.close()


def idle_writer_pid() -> int | None:
    """The process id of the writer kept for the next run (None: none is kept): its CPU time
    is the operating system's to report (it is reaped only when it stops)."""
    with _idle_lock:
        return _idle[0]._proc.pid if _idle else None
