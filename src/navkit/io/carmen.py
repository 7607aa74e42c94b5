"""CARMEN log files (plain or gzipped): ``FLASER`` laser scans and ``ODOM`` odometry.

The format (CARMEN ``logger``, also used by the Radish / Freiburg 2D laser datasets)::

    FLASER n r_1 ... r_n x y theta odom_x odom_y odom_theta ipc_timestamp ipc_hostname logger_timestamp
    ODOM x y theta tv rv accel ipc_timestamp ipc_hostname logger_timestamp

Ranges are metres; bearings span 180 degrees centred forward, ``linspace(-pi/2, pi/2, n)``
(``fov_deg`` overrides the span). In the ``*-corrected`` logs ``x y theta`` of a ``FLASER``
line is the SLAM-corrected laser pose, ``odom_*`` the raw odometry at the scan's time. Other
messages (``PARAM``, ``NEFF``, ``SYNC``, ``RLASER``, ...) and ``#`` comments are skipped (their
names are counted in :attr:`CarmenLog.skipped`).
"""

from __future__ import annotations

import gzip
import logging
import os
import zlib
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from navkit.errors import DataNotFoundError, FormatError, InputError

__all__ = ["CarmenLog", "read_carmen"]

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class CarmenLog:
    """The laser scans and odometry of a CARMEN log.

    Attributes
    ----------
    ranges : (K, B) float64 array
        Metres; NaN where the reading is not positive (no return).
    bearings : (B,) float64 array
        Beam angles in the laser frame, radians (0 forward, positive left).
    poses : (K, 3) float64 array
        ``(x, y, theta)`` of the laser at each scan (corrected pose in ``*-corrected`` logs).
    odom_poses : (K, 3) float64 array
        Raw odometry ``(x, y, theta)`` at each scan.
    timestamps : (K,) float64 array
        Logger timestamps of the scans, seconds. When they do not strictly increase (Radish logs
        with every timestamp 0) the scan order is used instead (scan ``k`` at ``k`` s), with a
        warning, so ``map build`` and ``map locate`` treat such logs alike.
    odom_t, odom_xytheta, odom_velocity : arrays
        ``ODOM`` messages: times ``(M,)``, poses ``(M, 3)``, ``(tv, rv)`` ``(M, 2)``.
    source : str
        The file the log came from.
    skipped : dict
        Message name -> count of lines that were not FLASER / ODOM.
    """

    ranges: NDArray[np.float64]
    bearings: NDArray[np.float64]
    poses: NDArray[np.float64]
    odom_poses: NDArray[np.float64]
    timestamps: NDArray[np.float64]
    odom_t: NDArray[np.float64]
    odom_xytheta: NDArray[np.float64]
    odom_velocity: NDArray[np.float64]
    source: str = ""
    skipped: dict[str, int] = field(default_factory=dict)

    def __len__(self) -> int:
        return len(self.ranges)

    def points(self, k: int, max_range: float = np.inf) -> NDArray[np.float64]:
        """End points ``(n, 2)`` of scan ``k`` in the laser frame (no-return and ``>= max_range`` dropped)."""
        r = self.ranges[k]
        ok = np.isfinite(r) & (r < max_range)
        return np.stack(
            [r[ok] * np.cos(self.bearings[ok]), r[ok] * np.sin(self.bearings[ok])], axis=1
        )


def _open_lines(path: Path) -> list[str]:
    try:
        with open(path, "rb") as fh:
            head = fh.read(2)
        if head == b"\x1f\x8b":
            with gzip.open(path, "rt", encoding="utf-8", errors="replace") as gz:
                return gz.read().splitlines()
        return path.read_text(encoding="utf-8", errors="replace").splitlines()
    except (OSError, EOFError, zlib.error) as exc:
        raise FormatError(
            f"cannot be read: {exc}", source=path, expected="a CARMEN log (text or gzip)"
        ) from exc


def read_carmen(path: str | os.PathLike[str], *, fov_deg: float = 180.0) -> CarmenLog:
    """Read a CARMEN log (``.log`` or ``.log.gz``).

    Parameters
    ----------
    path : path
    fov_deg : float
        Angular span of the laser, degrees (bearings ``linspace(-fov/2, fov/2, n)``).

    Raises
    ------
    DataNotFoundError
        If the file does not exist.
    FormatError
        On a truncated or corrupt file, a ``FLASER`` / ``ODOM`` line with too few fields or a
        non-numeric value (the message gives the line number), scans of differing beam counts,
        or a log without any ``FLASER`` line.
    """
    p = Path(path)
    if not p.is_file():
        raise DataNotFoundError(f"{p}: no such CARMEN log")
    if not (0 < fov_deg <= 360):
        raise InputError(f"is {fov_deg}", field="fov_deg", expected="in (0, 360]")
    lines = _open_lines(p)
    scans: list[list[float]] = []
    scan_lines: list[int] = []
    odom: list[list[float]] = []
    skipped: Counter[str] = Counter()
    n_beams: int | None = None
    for lineno, line in enumerate(lines, start=1):
        tok = line.split()
        if not tok or tok[0].startswith("#"):
            continue
        kind = tok[0]
        if kind == "FLASER":
            try:
                n = int(tok[1])
            except (IndexError, ValueError):
                raise FormatError(
                    f"line {lineno}: beam count is not an integer",
                    source=p,
                    field="FLASER",
                    expected="FLASER n r_1 .. r_n x y theta ...",
                ) from None
            need = 2 + n + 6 + 3
            if n <= 0 or len(tok) < need:
                raise FormatError(
                    f"line {lineno}: {len(tok)} fields for {n} beams",
                    source=p,
                    field="FLASER",
                    expected=f"{need} fields: FLASER n r_1..r_n x y theta odom_x odom_y odom_theta ipc_ts host logger_ts",
                )
            if n_beams is None:
                n_beams = n
            elif n != n_beams:
                raise FormatError(
                    f"line {lineno}: {n} beams after {n_beams}",
                    source=p,
                    field="FLASER",
                    expected="the same beam count in every scan",
                )
            try:
                values = [float(v) for v in tok[2 : 2 + n + 6]]
                values.append(float(tok[2 + n + 8]))  # logger timestamp
            except ValueError as exc:
                raise FormatError(
                    f"line {lineno}: {exc}",
                    source=p,
                    field="FLASER",
                    expected="numeric ranges, poses and timestamps",
                ) from None
            scans.append(values)
            scan_lines.append(lineno)
        elif kind == "ODOM":
            if len(tok) < 10:
                raise FormatError(
                    f"line {lineno}: {len(tok)} fields",
                    source=p,
                    field="ODOM",
                    expected="ODOM x y theta tv rv accel ipc_ts host logger_ts",
                )
            try:
                odom.append([float(v) for v in tok[1:6]] + [float(tok[9])])
            except ValueError as exc:
                raise FormatError(
                    f"line {lineno}: {exc}",
                    source=p,
                    field="ODOM",
                    expected="numeric x y theta tv rv accel and timestamps",
                ) from None
        else:
            skipped[kind] += 1
    if not scans or n_beams is None:
        raise FormatError(
            "no FLASER line", source=p, field="FLASER", expected="at least one laser scan"
        )
    S = np.asarray(scans, dtype=np.float64)
    R = S[:, :n_beams].copy()
    R[~(R > 0)] = np.nan
    bad = ~np.isfinite(S[:, n_beams:]).all(axis=1)
    if bad.any():
        raise FormatError(
            f"line {scan_lines[int(np.argmax(bad))]}: non-finite pose or timestamp",
            source=p,
            field="FLASER",
            expected="finite x y theta and timestamps",
        )
    odo = np.asarray(odom, dtype=np.float64).reshape(-1, 6)
    stamps = S[:, n_beams + 6].copy()
    if len(stamps) > 1 and not np.all(np.diff(stamps) > 0):
        # Radish logs (e.g. orebro) carry all-zero logger timestamps: time is the scan order
        log.warning(
            "%s: logger timestamps do not increase (%d of %d scans repeat or go back, all zero: "
            "%s); the scan order is used as time (scan k at k seconds)",
            p.name,
            int(np.sum(np.diff(stamps) <= 0)),
            len(stamps),
            bool(np.all(stamps == 0)),
        )
        stamps = np.arange(len(stamps), dtype=np.float64)
    half = np.radians(fov_deg) / 2
    out = CarmenLog(
        ranges=R,
        bearings=np.linspace(-half, half, n_beams),
        poses=S[:, n_beams : n_beams + 3].copy(),
        odom_poses=S[:, n_beams + 3 : n_beams + 6].copy(),
        timestamps=stamps,
        odom_t=odo[:, 5].copy(),
        odom_xytheta=odo[:, 0:3].copy(),
        odom_velocity=odo[:, 3:5].copy(),
        source=str(p),
        skipped=dict(skipped),
    )
    log.info("%s: %d scans of %d beams, %d odometry messages", p.name, len(R), n_beams, len(odo))
    return out
