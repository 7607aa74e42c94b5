"""Which implementation runs navkit's per-frame hot paths: the compiled kernels or their NumPy twins.

Every hot path has two implementations that give the same answers, bit for bit
(``docs/kernels.md``, "The equivalence contract"): Numba kernels (the ``_kernels*.py`` modules
of each capability, :data:`KERNEL_MODULES`) and their NumPy twins. The kernels are 2-7x faster per frame, but the first call on a
machine compiles them: about a minute of CPU for all of them on a 2-core machine, once, after
which they load from Numba's on-disk cache in under a second.

The policy, ``NAVKIT_JIT`` (environment variable; :func:`mode`):

``"auto"`` (default)
    A process whose kernels are already compiled for this machine (a **stamp** left by a
    complete warm-up, :func:`stamp_path`) uses the compiled kernels. A process that finds no
    stamp runs the NumPy twins **for its whole life**; what else it does is the application's
    choice (:func:`on_missing_kernels`): the command line starts one detached background
    compilation at idle priority (:func:`navkit.runtime.warmup.start_background`) that writes the
    stamp for the next runs; a library user's process starts nothing. A process never switches
    implementation half-way, so its results do not depend on when a compilation finished.
``"eager"``
    Always the compiled kernels; a kernel missing from the cache is compiled in this process on
    first use (the test suite and the benchmarks use this).
``"numpy"``
    Never the kernels (no Numba import, no compilation, nothing started).

:func:`use` overrides the policy in code, for the rest of the process or for a ``with`` block:
the one switch between kernels and twins.

``navkit compile`` (:func:`navkit.runtime.warmup.warm_up`) compiles everything in the foreground
and writes the stamp: the step for a robot's image or a container build.

Decisions:

- The stamp is keyed by what invalidates Numba's cache (each kernel module's modification time
  and size, Numba's and Python's versions, the machine and CPU model, ``NUMBA_CACHE_DIR``).
  A stale or missing cache entry behind a valid stamp costs an in-process compilation of that
  kernel (the ``"eager"`` behaviour), never a wrong answer.
- One switch: every function and online object with a kernel follows :func:`kernels_enabled`
  (the innermost :func:`use`, else the policy); none takes an argument or setting that chooses
  the implementation. An online object decides when it is built and keeps that decision.
"""

from __future__ import annotations

import hashlib
import logging
import os
import platform
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass
from importlib import metadata
from pathlib import Path

from navkit.errors import ConfigError

__all__ = [
    "KERNEL_MODULES",
    "MODES",
    "JitStatus",
    "failed_path",
    "implementation",
    "kernels_enabled",
    "lock_is_fresh",
    "lock_path",
    "mode",
    "on_missing_kernels",
    "stamp_path",
    "status",
    "use",
    "write_stamp",
]

log = logging.getLogger(__name__)

MODES = ("auto", "eager", "numpy")
ENV = "NAVKIT_JIT"

KERNEL_MODULES = (
    "geometry/_kernels.py",
    "geometry/_kernels_math.py",
    "localization/_kernels.py",
    "obstacles/_kernels_common.py",
    "obstacles/_kernels_grid.py",
    "obstacles/_kernels_map.py",
    "obstacles/_kernels_mesh.py",
    "path/_kernels.py",
    "planes/_kernels.py",
    "planes/_kernels_dense.py",
    "planes/_kernels_outline.py",
    "stereo/_kernels.py",
)
"""Every module with Numba kernels, relative to the package (their stamps key the cache)."""

_PKG = Path(__file__).resolve().parent
_STALE_LOCK_S = 1800.0  # a warm-up lock older than this is from a process that died
_decision: bool | None = None


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


def lock_path() -> Path:
    """The lock file a warm-up holds while it compiles (its pid inside; stale after 30 min)."""
    return stamp_path().with_suffix(".lock")


def lock_is_fresh(lock: Path) -> bool:
    """Whether a warm-up lock was written less than 30 min ago (older: its process died)."""
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
        lock_is_fresh(lock_path()),
        failed_path().exists(),
        _decision,
    )


MissingKernelsHook = Callable[[], bool]
"""What a process under ``auto`` does when it finds no stamp: start the compilation elsewhere and
return True (this process then runs the twins), or return False (compile in this process)."""

_on_missing: MissingKernelsHook | None = None


def on_missing_kernels(hook: MissingKernelsHook | None) -> None:
    """Register what happens under ``auto`` when the kernels are not compiled on this machine.

    The library itself starts nothing: with no hook such a process runs the NumPy twins and logs
    once how to compile them. The command line registers
    :func:`navkit.runtime.warmup.start_background` (one detached compilation at idle priority,
    for the next runs); an application may register its own, or ``None`` to clear it.
    """
    global _on_missing
    _on_missing = hook


def _policy_decision() -> bool:
    m = mode()
    if m == "eager":
        return True
    if m == "numpy":
        return False
    try:
        if stamp_path().is_file():
            return True
    except OSError as exc:  # unwritable folders: behave as if no policy existed (compile here)
        log.info("no kernel stamp (%s): compiling in this process", exc)
        return True
    if _on_missing is None:
        log.info(
            "navkit's compiled kernels are not built on this machine: this process runs their "
            "NumPy twins (the same results, slower); `navkit compile` builds them"
        )
        return False
    try:
        return not _on_missing()
    except OSError as exc:  # no new process could be started: compile in this process
        log.info("the kernels' background compilation could not start (%s): compiling here", exc)
        return True


def kernels_enabled() -> bool:
    """Whether the compiled kernels run here: the innermost :func:`use` in force, else the
    process's policy (decided once, on the first call, and kept)."""
    global _decision
    if _override:
        return _override[-1]
    if _decision is None:
        _decision = _policy_decision()
    return _decision


_override: list[bool] = []


class use:
    """Choose the implementation: ``"eager"`` (the compiled kernels, compiled on first use),
    ``"numpy"`` (their NumPy twins) or ``"auto"`` (the process's policy, ``NAVKIT_JIT``).

    ``jit.use("numpy")`` holds for the rest of the process; ``with jit.use("numpy"): ...`` for the
    block only. The one switch of the whole package: every function with a kernel follows it; an
    online object keeps the implementation it was built with (build it inside the block).
    """

    def __init__(self, implementation: str) -> None:
        if implementation not in MODES:
            raise ConfigError(
                f"= {implementation!r}", field="implementation", expected=f"one of {MODES}"
            )
        if implementation == "auto":
            _override.append(_policy_decision() if _decision is None else _decision)
        else:
            _override.append(implementation == "eager")
        self._depth = len(_override)

    def __enter__(self) -> use:
        return self

    def __exit__(self, *exc: object) -> None:
        del _override[self._depth - 1 :]


def implementation() -> str:
    """What this process ran so far: ``"compiled kernels"``, ``"NumPy twins"``, or ``"no
    kernel needed"`` (nothing asked yet) - written into every run's ``summary.json`` so that
    its timings can be read (a first run on a fresh machine runs the twins)."""
    decided = _override[-1] if _override else _decision
    if decided is None:
        return "no kernel needed"
    return "compiled kernels" if decided else "NumPy twins"
