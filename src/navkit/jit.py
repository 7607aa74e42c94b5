"""Which implementation runs navkit's per-frame hot paths: the compiled kernels or their NumPy twins.

Every hot path has two implementations that give the same answers (labels and ids identical,
floats within 1e-9 relative; ``docs/kernels.md``): Numba kernels (``_kernels.py`` of each
capability) and their NumPy twins. The kernels are 2-7x faster per frame, but the first call on a
machine compiles them: about a minute of CPU for all of them on a 2-core machine, once, after
which they load from Numba's on-disk cache in under a second.

The policy, ``NAVKIT_JIT`` (environment variable; :func:`mode`):

``"auto"`` (default)
    A process whose kernels are already compiled for this machine (a **stamp** left by a
    complete warm-up, :func:`stamp_path`) uses the compiled kernels. A process that finds no
    stamp runs the NumPy twins **for its whole life** and starts one background process
    (``python -m navkit.runtime.warmup``, detached, at the idle CPU priority) that compiles every kernel into the
    cache and then writes the stamp: the first run on a fresh machine costs what it cost before
    the kernels existed, and every later run is fast. A process never switches implementation
    half-way, so its results do not depend on when a compilation finished.
``"eager"``
    Always the compiled kernels; a kernel missing from the cache is compiled in this process on
    first use (the test suite and the benchmarks use this).
``"numpy"``
    Never the kernels (no Numba import, no compilation, nothing started).

``navkit compile`` (:func:`navkit.runtime.warmup.warm_up`) compiles everything in the foreground
and writes the stamp: the step for a robot's image or a container build.

Decisions (written down here because nobody can be asked):

- The two implementations agree to 1e-9 relative per call, not bit for bit everywhere: a long
  closed loop (the mission) can amplify such differences, so the first run on a fresh machine
  and later runs may differ in the last digits of their figures, never in what the tests pin
  for a single frame.
- The stamp is keyed by what invalidates Numba's cache (each kernel module's modification time
  and size, Numba's and Python's versions, the machine and CPU model, ``NUMBA_CACHE_DIR``).
  A stale or missing cache entry behind a valid stamp costs an in-process compilation of that
  kernel (the ``"eager"`` behaviour), never a wrong answer.
- Explicit requests win: a function called with ``compiled=True`` (or ``backend="compiled"``)
  runs the kernel whatever the policy; the defaults (``compiled=None``, ``backend="auto"``, the
  ``compiled`` attribute an online object sets from :func:`kernels_enabled` when it is built)
  follow it.
"""

from __future__ import annotations

import hashlib
import logging
import os
import platform
import subprocess
import sys
import time
from dataclasses import dataclass
from importlib import metadata
from pathlib import Path

from navkit.errors import ConfigError

__all__ = [
    "BACKENDS",
    "KERNEL_MODULES",
    "MODES",
    "JitStatus",
    "failed_path",
    "implementation",
    "kernels_enabled",
    "mode",
    "resolve",
    "resolve_backend",
    "stamp_path",
    "status",
    "write_stamp",
]

log = logging.getLogger(__name__)

MODES = ("auto", "eager", "numpy")
ENV = "NAVKIT_JIT"

KERNEL_MODULES = (
    "geometry/_kernels.py",
    "localization/_kernels.py",
    "obstacles/_kernels.py",
    "obstacles/_kernels_map.py",
    "path/_kernels.py",
    "planes/_kernels.py",
    "stereo/_kernels.py",
)
"""Every module with Numba kernels, relative to the package (their stamps key the cache)."""

_PKG = Path(__file__).resolve().parent
_STALE_LOCK_S = 1800.0  # a warm-up lock older than this is from a process that died
_decision: bool | None = None
_background: subprocess.Popen[bytes] | None = None  # the warm-up this process started


def mode() -> str:
    """The policy from ``NAVKIT_JIT`` (``"auto"`` when unset or empty)."""
    value = os.environ.get(ENV, "").strip().lower() or "auto"
    if value not in MODES:
        raise ConfigError(
            f"= {value!r}", source=f"environment variable {ENV}", expected=f"one of {MODES}"
        )
    return value


def _cpu_model() -> str:
    try:
        with open("/proc/cpuinfo", encoding="utf-8", errors="replace") as f:
            for line in f:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor()


def _key() -> str:
    """What Numba's cache depends on, hashed."""
    parts = [sys.version, platform.machine(), _cpu_model(), os.environ.get("NUMBA_CACHE_DIR", "")]
    try:
        parts.append(metadata.version("numba"))
    except metadata.PackageNotFoundError:
        parts.append("no numba")
    for rel in KERNEL_MODULES:
        st = (_PKG / rel).stat()
        parts.append(f"{rel}:{st.st_mtime_ns}:{st.st_size}")
    return hashlib.sha256("\n".join(parts).encode()).hexdigest()[:16]


def _stamp_dir() -> Path:
    """Where the stamp lives: beside Numba's cache (``NUMBA_CACHE_DIR``, else the package's
    ``__pycache__`` when writable - where Numba writes too - else the user's cache folder)."""
    if os.environ.get("NUMBA_CACHE_DIR"):
        return Path(os.environ["NUMBA_CACHE_DIR"])
    in_tree = _PKG / "__pycache__"
    try:
        in_tree.mkdir(exist_ok=True)
        if os.access(in_tree, os.W_OK):
            return in_tree
    except OSError:
        pass
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "navkit"


def stamp_path() -> Path:
    """The stamp a complete warm-up writes for this machine, Numba, Python and kernel sources."""
    return _stamp_dir() / f"navkit-jit-{_key()}.ok"


def write_stamp() -> Path:
    """Mark the kernels as compiled (called by a warm-up after every kernel ran once)."""
    path = stamp_path()
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(f".tmp{os.getpid()}")
    tmp.write_text(f"compiled {time.strftime('%Y-%m-%dT%H:%M:%S')} by pid {os.getpid()}\n")
    os.replace(tmp, path)
    return path


@dataclass(frozen=True)
class JitStatus:
    """What :func:`status` reports."""

    mode: str
    stamp: Path
    compiled: bool  # the stamp exists
    warming: bool  # a warm-up process holds the lock
    failed: bool  # a background warm-up failed (its traceback in failed_path())
    enabled: bool | None  # this process's decision, None until made


def _lock_path() -> Path:
    return stamp_path().with_suffix(".lock")


def _lock_is_fresh(lock: Path) -> bool:
    try:
        return time.time() - lock.stat().st_mtime < _STALE_LOCK_S
    except OSError:
        return False


def failed_path() -> Path:
    """Where a failed background warm-up leaves its traceback (removed by a successful one)."""
    return stamp_path().with_suffix(".failed")


def status() -> JitStatus:
    """The policy, the stamp and this process's decision (``navkit compile --status``)."""
    stamp = stamp_path()
    return JitStatus(
        mode(),
        stamp,
        stamp.is_file(),
        _lock_is_fresh(_lock_path()),
        failed_path().exists(),
        _decision,
    )


def _start_warmup() -> None:
    """Start one detached ``python -m navkit.runtime.warmup --stamp`` (idle CPU priority) unless
    one runs."""
    global _background
    lock = _lock_path()
    lock.parent.mkdir(parents=True, exist_ok=True)
    if failed_path().exists():
        log.warning(
            "the background compilation of navkit's kernels failed (%s): this run uses their "
            "NumPy twins; `navkit compile` shows the error",
            failed_path(),
        )
        return
    if lock.exists() and not _lock_is_fresh(lock):
        lock.unlink(missing_ok=True)
    try:
        fd = os.open(lock, os.O_CREAT | os.O_EXCL | os.O_WRONLY, 0o644)
    except FileExistsError:
        log.info("navkit's kernels are being compiled by another process; NumPy twins run here")
        return
    env = dict(os.environ, **{ENV: "eager"})
    logfile = lock.with_suffix(".log")
    try:
        with open(logfile, "wb") as out:
            proc = subprocess.Popen(
                [sys.executable, "-m", "navkit.runtime.warmup", "--stamp", "--lock", str(lock)],
                env=env,
                stdin=subprocess.DEVNULL,
                stdout=out,
                stderr=subprocess.STDOUT,
                start_new_session=True,
            )
    except OSError:  # no process could be started: leave no lock behind (the caller compiles)
        os.close(fd)
        lock.unlink(missing_ok=True)
        raise
    _background = proc  # kept: it outlives this call (and may outlive the process)
    os.write(fd, f"{proc.pid}\n".encode())
    os.close(fd)
    log.info(
        "navkit's compiled kernels are not built on this machine yet: this run uses their NumPy "
        "twins (same results, slower) while process %d compiles them for the next runs "
        "(`navkit compile` does it in the foreground; NAVKIT_JIT=eager|numpy to choose)",
        proc.pid,
    )


def kernels_enabled() -> bool:
    """Whether this process runs the compiled kernels (decided once, on the first call)."""
    global _decision
    if _decision is None:
        m = mode()
        if m == "eager":
            _decision = True
        elif m == "numpy":
            _decision = False
        else:
            try:
                _decision = stamp_path().is_file()
                if not _decision:
                    _start_warmup()
            except OSError as exc:  # unwritable folders, no new process: behave as before
                log.info("no kernel stamp (%s): compiling in this process", exc)
                _decision = True
    return _decision


def implementation() -> str:
    """What this process ran so far: ``"compiled kernels"``, ``"NumPy twins"``, or ``"no
    kernel needed"`` (nothing asked yet) - written into every run's ``summary.json`` so that
    its timings can be read (a first run on a fresh machine runs the twins)."""
    if _decision is None:
        return "no kernel needed"
    return "compiled kernels" if _decision else "NumPy twins"


def resolve(compiled: bool | None) -> bool:
    """An explicit ``True``/``False`` as given; ``None`` (a default) as :func:`kernels_enabled`."""
    return kernels_enabled() if compiled is None else bool(compiled)


BACKENDS = ("auto", "compiled", "numpy")
"""Values of a ``backend`` setting: ``"auto"`` follows the policy, the others are explicit."""


def resolve_backend(backend: str, *, field: str = "backend") -> str:
    """``"compiled"`` or ``"numpy"`` for a ``backend`` setting (``"auto"`` as
    :func:`kernels_enabled`); anything else is a :class:`~navkit.errors.ConfigError`."""
    if backend not in BACKENDS:
        raise ConfigError(f"= {backend!r}", field=field, expected=f"one of {BACKENDS}")
    if backend == "auto":
        return "compiled" if kernels_enabled() else "numpy"
    return backend
