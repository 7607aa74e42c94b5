"""Run many independent inputs (files, logs, seeds) through one navkit function, here or on Dask.

One *task* is one input: a picklable module-level function, its keyword arguments (paths and
small settings, never large arrays: workers read their inputs themselves) and a hash of the
resolved settings and the input's identity. A worker calls ``fn(out_dir, **kwargs)``, which writes
its outputs under ``out_dir`` (atomically, like every navkit writer) and returns a small mapping
of key figures. When it returns, the worker writes a completion marker
(:data:`DONE_MARKER`: the settings hash, the figures and the sizes of the files written), so a
later ``resume=True`` run knows the input is complete and skips it.

Three ways to execute, with identical outputs:

- neither ``workers`` nor ``scheduler``: an in-process loop (no Dask needed);
- ``workers=N``: a ``dask.distributed.LocalCluster`` of N single-threaded worker processes;
- ``scheduler="tcp://host:8786"``: an existing Dask cluster (dask-ssh, dask-jobqueue, Kubernetes).

A failing input never stops the batch: its row in the manifest says ``failed`` with the error's
one line. A worker process that dies in a task (killed, out of memory) is replaced by Dask and the
task retried on another worker, up to Dask's ``distributed.scheduler.allowed-failures``; after that
the input is recorded as failed.

The manifest ``batch.jsonl`` gets one JSON row per input as it completes (flushed, so a killed
driver leaves every finished row), and is rewritten in input order when the batch ends.
"""

from __future__ import annotations

import hashlib
import json
import logging
import os
import shutil
import socket
import time
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from navkit.errors import ConfigError, NavkitError, require_module
from navkit.io.atomic import to_jsonable, write_json

__all__ = [
    "DONE_MARKER",
    "MANIFEST",
    "BatchResult",
    "BatchSettings",
    "BatchTask",
    "execute_task",
    "is_complete",
    "iter_batch",
    "local_cluster",
    "run_batch",
    "settings_hash",
]

log = logging.getLogger(__name__)

DONE_MARKER = ".navkit-done.json"
MANIFEST = "batch.jsonl"
_KEY_CHARS = set("abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ0123456789._-")


@dataclass(frozen=True)
class BatchSettings:
    """How a batch runs.

    Parameters
    ----------
    workers : int, optional
        Start a ``LocalCluster`` with this many single-threaded worker processes.
    scheduler : str, optional
        Address of an existing Dask scheduler (``tcp://host:8786``). Exclusive with ``workers``.
    resume : bool
        Skip inputs whose outputs are complete and whose settings hash matches.
    retries : int
        Extra attempts Dask makes for a task that raised an unexpected (non-navkit) error.
    """

    workers: int | None = None
    scheduler: str | None = None
    resume: bool = False
    retries: int = 0

    def __post_init__(self) -> None:
        if self.workers is not None and self.scheduler is not None:
            raise ConfigError(
                "give either a number of local workers or a scheduler address, not both",
                source="batch",
                field="workers/scheduler",
                expected="one of --workers N or --scheduler ADDRESS",
            )
        if self.workers is not None and not 1 <= int(self.workers) <= 1024:
            raise ConfigError(
                f"{self.workers} workers",
                source="batch",
                field="workers",
                expected="an integer from 1 to 1024",
            )
        if not 0 <= int(self.retries) <= 10:
            raise ConfigError(
                f"{self.retries} retries", source="batch", field="retries", expected="0 to 10"
            )

    @property
    def distributed(self) -> bool:
        """True when the batch runs on Dask rather than in this process."""
        return self.workers is not None or self.scheduler is not None


@dataclass(frozen=True)
class BatchTask:
    """One input of a batch.

    Parameters
    ----------
    key : str
        Unique, file-system safe name; the task's outputs go to ``out / key``.
    fn : callable
        Module-level (picklable) function ``fn(out_dir: Path, **kwargs) -> Mapping[str, Any]``
        returning small JSON-able key figures.
    kwargs : mapping
        Its arguments: paths and small settings.
    settings_hash : str
        Hash of everything that determines the outputs (see :func:`settings_hash`).
    """

    key: str
    fn: Callable[..., Mapping[str, Any]]
    kwargs: Mapping[str, Any] = field(default_factory=dict)
    settings_hash: str = ""

    def __post_init__(self) -> None:
        if not self.key or not set(self.key) <= _KEY_CHARS or self.key in {".", ".."}:
            raise ConfigError(
                f"task key {self.key!r}",
                source="batch",
                field="key",
                expected="letters, digits, '.', '_' or '-'",
            )


@dataclass(frozen=True)
class BatchResult:
    """The rows of the manifest, in input order, and where they were written."""

    rows: tuple[dict[str, Any], ...]
    manifest: Path

    @property
    def n_failed(self) -> int:
        return sum(r["status"] == "failed" for r in self.rows)

    @property
    def n_ok(self) -> int:
        return sum(r["status"] == "ok" for r in self.rows)

    @property
    def n_skipped(self) -> int:
        return sum(r["status"] == "skipped" for r in self.rows)


def settings_hash(*parts: Any) -> str:
    """A stable hash of settings and input identities (dataclasses, dicts, paths, numbers).

    A path is hashed with its resolved name, size and modification time, so an input file that
    changed makes its task run again on ``--resume``.
    """

    def ident(p: Any) -> Any:
        if isinstance(p, Path):
            try:
                st = p.stat()
                return [str(p.resolve()), st.st_size, st.st_mtime_ns]
            except OSError:
                return [str(p)]
        return p

    text = json.dumps(to_jsonable([ident(p) for p in parts]), sort_keys=True, default=str)
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def _files_of(out_dir: Path) -> dict[str, int]:
    files = {}
    for p in sorted(out_dir.rglob("*")):
        if p.is_file() and p.name != DONE_MARKER and not p.name.startswith("."):
            files[str(p.relative_to(out_dir))] = p.stat().st_size
    return files


def is_complete(out_dir: Path, settings_hash_: str) -> dict[str, Any] | None:
    """The completion marker of ``out_dir`` when its outputs are complete for these settings."""
    marker = out_dir / DONE_MARKER
    try:
        done = json.loads(marker.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    if not isinstance(done, dict) or done.get("settings_hash") != settings_hash_:
        return None
    files = done.get("files")
    if not isinstance(files, dict):
        return None
    for name, size in files.items():
        p = out_dir / name
        if not p.is_file() or p.stat().st_size != size:
            return None
    return done


def _worker_name() -> str:
    return f"{socket.gethostname()}:{os.getpid()}"


def execute_task(task: BatchTask, out: str) -> dict[str, Any]:
    """Run one task where it is called (a worker or this process) and return its manifest row."""
    out_dir = Path(out) / task.key
    t0 = time.perf_counter()
    row: dict[str, Any] = {"key": task.key, "worker": _worker_name()}
    new_dir = not out_dir.exists()
    try:
        out_dir.mkdir(parents=True, exist_ok=True)
        figures = dict(task.fn(out_dir, **dict(task.kwargs)) or {})
    except NavkitError as exc:
        row.update(status="failed", error=str(exc), figures={})
    except Exception as exc:  # one bad input never stops the batch; the row says what happened
        log.debug("task %s raised", task.key, exc_info=True)
        row.update(
            status="failed", error=f"internal error: {type(exc).__name__}: {exc}", figures={}
        )
    else:
        row.update(status="ok", error=None, figures=to_jsonable(figures))
        write_json(
            out_dir / DONE_MARKER,
            {
                "settings_hash": task.settings_hash,
                "figures": row["figures"],
                "files": _files_of(out_dir),
            },
        )
    if row["status"] == "failed" and new_dir:
        # a failed input leaves no folder (its partial files are not results): the manifest
        # row says why it failed
        shutil.rmtree(out_dir, ignore_errors=True)
    row["seconds"] = round(time.perf_counter() - t0, 6)
    return row


class _Manifest:
    """``batch.jsonl``: rows appended (and flushed) as inputs complete."""

    def __init__(self, out: Path) -> None:
        self.path = out / MANIFEST
        self._fh = open(self.path, "w", encoding="utf-8")

    def add(self, row: Mapping[str, Any]) -> None:
        self._fh.write(json.dumps(to_jsonable(row), sort_keys=True) + "\n")
        self._fh.flush()

    def close(self, rows: Sequence[Mapping[str, Any]]) -> None:
        self._fh.close()
        from navkit.io.atomic import write_text

        write_text(
            self.path, "".join(json.dumps(to_jsonable(r), sort_keys=True) + "\n" for r in rows)
        )


def _run_local(todo: Sequence[BatchTask], out: Path) -> Iterator[dict[str, Any]]:
    from navkit.io.atomic import current_transaction

    for task in todo:
        row = execute_task(task, str(out))
        # inside a command's output transaction, a completed input is kept even if the run is
        # interrupted later (its marker lets --resume skip it); only the input in flight is undone
        txn = current_transaction()
        if txn is not None:
            txn.commit()
        yield row


_ONE_THREAD = {
    name: "1"
    for name in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS")
}


def local_cluster(workers: int):  # type: ignore[no-untyped-def]
    """A ``LocalCluster`` of ``workers`` single-threaded processes (its HTTP server on a free port).

    Each worker's maths libraries get one thread: with one worker per core, more threads only
    fight over the same cores.
    """
    distributed = require_module("distributed", "cluster", "running a batch on Dask")
    return distributed.LocalCluster(
        n_workers=workers,
        threads_per_worker=1,
        processes=True,
        dashboard_address=":0",  # any free port: never clashes with another cluster
        env=_ONE_THREAD,
    )


def _run_dask(
    todo: Sequence[BatchTask], out: Path, settings: BatchSettings
) -> Iterator[dict[str, Any]]:
    distributed = require_module("distributed", "cluster", "running a batch on Dask")
    # Dask's own INFO lines (scheduler start/stop) are noise on a command line
    quiet = logging.getLogger("distributed")
    quiet.setLevel(max(quiet.getEffectiveLevel(), logging.WARNING))
    cluster = None
    if settings.scheduler is not None:
        client = distributed.Client(settings.scheduler)
    else:
        cluster = local_cluster(int(settings.workers or 1))
        client = distributed.Client(cluster)
    try:
        futures = {
            client.submit(
                execute_task,
                task,
                str(out),
                key=f"navkit-{task.key}-{task.settings_hash or 'x'}",
                pure=False,
                retries=settings.retries,
            ): task
            for task in todo
        }
        for fut in distributed.as_completed(futures):
            task = futures[fut]
            try:
                yield fut.result()
            except Exception as exc:  # KilledWorker and friends: the input is recorded as failed
                yield {
                    "key": task.key,
                    "status": "failed",
                    "error": f"{type(exc).__name__}: {exc}",
                    "figures": {},
                    "seconds": None,
                    "worker": None,
                }
    finally:
        client.close()
        if cluster is not None:
            cluster.close()


def iter_batch(
    tasks: Sequence[BatchTask],
    out: str | os.PathLike[str],
    settings: BatchSettings | None = None,
) -> Iterator[dict[str, Any]]:
    """Run every task and yield each manifest row as its input completes (skipped ones first).

    The manifest ``out / batch.jsonl`` is appended row by row and rewritten in input order when
    the generator finishes (or is closed early).

    Parameters
    ----------
    tasks : sequence of BatchTask
        The inputs, with unique keys.
    out : path
        The batch's output folder; task ``k`` writes under ``out / k``.
    settings : BatchSettings, optional
        Local loop (default), LocalCluster or an existing scheduler; resume; retries.
    """
    settings = settings or BatchSettings()
    keys = [t.key for t in tasks]
    if len(set(keys)) != len(keys):
        dup = sorted({k for k in keys if keys.count(k) > 1})
        raise ConfigError(
            f"inputs share output names {dup[:5]}",
            source="batch",
            field="key",
            expected="one output folder per input (rename or move the inputs)",
        )
    out_path = Path(out)
    out_path.mkdir(parents=True, exist_ok=True)
    manifest = _Manifest(out_path)
    rows: dict[str, dict[str, Any]] = {}
    try:
        todo = []
        for task in tasks:
            done = is_complete(out_path / task.key, task.settings_hash) if settings.resume else None
            if done is None:
                todo.append(task)
                continue
            row = {
                "key": task.key,
                "status": "skipped",
                "error": None,
                "figures": done.get("figures", {}),
                "seconds": 0.0,
                "worker": None,
            }
            rows[task.key] = row
            manifest.add(row)
            yield row
        if settings.distributed:
            runner = _run_dask(todo, out_path, settings)
        else:
            runner = _run_local(todo, out_path)
        for row in runner:
            rows[row["key"]] = row
            manifest.add(row)
            yield row
    finally:
        manifest.close([rows[k] for k in keys if k in rows])


def run_batch(
    tasks: Sequence[BatchTask],
    out: str | os.PathLike[str],
    settings: BatchSettings | None = None,
) -> BatchResult:
    """Run every task (see :func:`iter_batch`) and return the manifest's rows in input order."""
    by_key = {row["key"]: row for row in iter_batch(tasks, out, settings)}
    ordered = tuple(by_key[t.key] for t in tasks if t.key in by_key)
    log.info(
        "batch: %d ok, %d skipped, %d failed",
        sum(r["status"] == "ok" for r in ordered),
        sum(r["status"] == "skipped" for r in ordered),
        sum(r["status"] == "failed" for r in ordered),
    )
    return BatchResult(rows=ordered, manifest=Path(out) / MANIFEST)
