"""Trajectory files: TUM, KITTI odometry poses, EuRoC ground truth, odometry logs.

Every reader returns a :class:`Trajectory` of stacked ``(N, 4, 4)`` poses ``T_world_body`` (the
file's own world and body frames, unchanged) and ``(N,)`` timestamps in seconds, and validates
what it reads: blank lines and ``#`` comments are skipped, a line with the wrong number of
columns, a non-numeric or non-finite value, a zero quaternion or timestamps going backwards is a
:class:`navkit.errors.FormatError` naming the file and the line number.

Decision on repeated timestamps: some published files repeat a timestamp (TUM fr2_desk ground
truth, line 10863, from rounding to 0.1 ms). By default (``duplicates="drop"``) the later row is
dropped with a logged warning so such files load; ``duplicates="error"`` makes it an error. A
timestamp *smaller* than its predecessor is always an error.
"""

from __future__ import annotations

import logging
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from navkit.domains import Domain
from navkit.errors import DataNotFoundError, FormatError, InputError
from navkit.geometry import se3_from_xyz_quat, se3_to_xyz_quat
from navkit.io.atomic import atomic_write

__all__ = [
    "Trajectory",
    "load_planar_track",
    "looks_like_odometry",
    "read_euroc",
    "read_kitti_poses",
    "read_odometry_log",
    "read_trajectory",
    "read_tum",
    "write_kitti_poses",
    "write_tum",
]

log = logging.getLogger(__name__)

PathLike = str | os.PathLike[str]
Duplicates = Literal["drop", "error"]


@dataclass(frozen=True, eq=False)
class Trajectory:
    """Timed rigid poses.

    Parameters
    ----------
    timestamps : (N,) float64
        Seconds, finite and strictly increasing.
    poses : (N, 4, 4) float64
        ``T_world_body`` homogeneous transforms (maps body-frame points into the world frame).

    Raises
    ------
    InputError
        If shapes disagree, values are not finite or timestamps do not strictly increase (the
        message gives the first offending index).
    """

    timestamps: NDArray[np.float64]
    poses: NDArray[np.float64]

    def __post_init__(self) -> None:
        t = np.asarray(self.timestamps, dtype=np.float64)
        T = np.asarray(self.poses, dtype=np.float64)
        if t.ndim != 1 or T.shape != (len(t), 4, 4):
            raise InputError(
                f"timestamps {t.shape} and poses {T.shape}",
                field="poses",
                expected="timestamps (N,) and poses (N, 4, 4)",
            )
        bad = np.flatnonzero(~np.isfinite(t) | ~np.isfinite(T).all(axis=(1, 2)))
        if bad.size:
            raise InputError(
                f"pose {bad[0]} is not finite", field="poses", expected="finite values"
            )
        back = np.flatnonzero(np.diff(t) <= 0)
        if back.size:
            i = back[0] + 1
            raise InputError(
                f"timestamp {i} ({float(t[i])!r}) is not after timestamp {i - 1} ({float(t[i - 1])!r})",
                field="timestamps",
                expected="strictly increasing timestamps",
            )
        object.__setattr__(self, "timestamps", t)
        object.__setattr__(self, "poses", T)

    def __len__(self) -> int:
        return len(self.timestamps)

    @property
    def positions(self) -> NDArray[np.float64]:
        """``(N, 3)`` positions (the translation of each pose)."""
        return self.poses[:, :3, 3]

    @property
    def rotations(self) -> NDArray[np.float64]:
        """``(N, 3, 3)`` rotation matrices."""
        return self.poses[:, :3, :3]

    @property
    def orientations_quat_xyzw(self) -> NDArray[np.float64]:
        """``(N, 4)`` unit quaternions, scalar last, ``w >= 0``."""
        return se3_to_xyz_quat(self.poses)[1]

    @property
    def path_length(self) -> float:
        """Length of the polyline through the positions (metres)."""
        if len(self) < 2:
            return 0.0
        return float(np.linalg.norm(np.diff(self.positions, axis=0), axis=1).sum())

    def __getitem__(self, index: slice | NDArray[np.bool_] | NDArray[np.int_]) -> Trajectory:
        """A sub-trajectory (slice, boolean mask or increasing indices)."""
        return Trajectory(self.timestamps[index], self.poses[index])


# --------------------------------------------------------------------------- text tables
def _existing(path: PathLike) -> Path:
    p = Path(path)
    if not p.is_file():
        raise DataNotFoundError(f"{p}: no such file")
    return p


@dataclass(frozen=True)
class _Table:
    values: NDArray[np.float64]  # (N, ncol)
    tokens: NDArray[np.str_]  # (N, ncol) the original text (for exact integer parsing)
    lines: NDArray[np.int64]  # (N,) 1-based line numbers
    comments: list[str]


def _read_table(
    p: Path,
    ncols: tuple[int, ...] | int,
    what: str,
    *,
    delimiter: str | None = None,
    min_cols: bool = False,
) -> _Table:
    """Parse a numeric text table: skip blanks and '#' comments, check the column count per line.

    ``ncols``: accepted column counts (or the minimum with ``min_cols``); extra columns beyond the
    first accepted count are dropped when ``min_cols`` is set.
    """
    text = p.read_text(encoding="utf-8", errors="replace")
    raw = text.splitlines()
    comments = [ln for ln in raw if ln.lstrip().startswith("#")]
    keep = [
        (k + 1, ln) for k, ln in enumerate(raw) if ln.strip() and not ln.lstrip().startswith("#")
    ]
    accepted = (ncols,) if isinstance(ncols, int) else ncols
    if not keep:
        return _Table(
            np.zeros((0, accepted[0])),
            np.zeros((0, accepted[0]), dtype=str),
            np.zeros(0, np.int64),
            comments,
        )
    rows = [ln.replace(delimiter, " ").split() if delimiter else ln.split() for _, ln in keep]
    lengths = np.fromiter((len(r) for r in rows), dtype=np.int64, count=len(rows))
    lines = np.fromiter((k for k, _ in keep), dtype=np.int64, count=len(keep))
    want = accepted[0]
    if min_cols:
        bad = np.flatnonzero(lengths < want)
    else:
        if np.isin(lengths[0], accepted):
            want = int(lengths[0])
        bad = np.flatnonzero(lengths != want)
    if bad.size:
        i = bad[0]
        exp = f"at least {want}" if min_cols else " or ".join(str(c) for c in accepted)
        raise FormatError(
            f"line {lines[i]} has {lengths[i]} columns",
            source=p,
            field=f"line {lines[i]}",
            expected=f"{exp} columns ({what})",
        )
    if min_cols:
        rows = [r[:want] for r in rows]
    tokens = np.array(rows, dtype=str)
    try:
        values = tokens.astype(np.float64)
    except ValueError:
        # find the first offending line for the message (only on the error path)
        for i, r in enumerate(rows):
            try:
                [float(v) for v in r]
            except ValueError:
                raise FormatError(
                    f"line {lines[i]} is not numeric: {' '.join(r)[:60]!r}",
                    source=p,
                    field=f"line {lines[i]}",
                    expected=f"numbers ({what})",
                ) from None
        raise
    bad = np.flatnonzero(~np.isfinite(values).all(axis=1))
    if bad.size:
        i = bad[0]
        raise FormatError(
            f"line {lines[i]} holds a non-finite value (NaN or inf)",
            source=p,
            field=f"line {lines[i]}",
            expected="finite numbers",
        )
    return _Table(values, tokens, lines, comments)


def _check_times(
    p: Path, t: NDArray[np.float64], lines: NDArray[np.int64], duplicates: Duplicates
) -> NDArray[np.bool_]:
    """Mask of rows to keep; errors on timestamps going backwards (or repeated, if strict)."""
    if duplicates not in ("drop", "error"):
        raise InputError(f"{duplicates!r}", field="duplicates", expected="'drop' or 'error'")
    d = np.diff(t)
    back = np.flatnonzero(d < 0)
    if back.size:
        i = back[0] + 1
        raise FormatError(
            f"line {lines[i]}: timestamp {float(t[i])!r} is before the previous one {float(t[i - 1])!r} "
            f"(line {lines[i - 1]})",
            source=p,
            field=f"line {lines[i]}",
            expected="strictly increasing timestamps",
        )
    same = np.flatnonzero(d == 0) + 1
    keep = np.ones(len(t), dtype=bool)
    if same.size:
        if duplicates == "error":
            i = same[0]
            raise FormatError(
                f"line {lines[i]}: timestamp {float(t[i])!r} repeats the previous line's",
                source=p,
                field=f"line {lines[i]}",
                expected="strictly increasing timestamps (or duplicates='drop')",
            )
        log.warning(
            "%s: %d repeated timestamps (first at line %d) dropped, keeping the first row",
            p,
            same.size,
            lines[same[0]],
        )
        keep[same] = False
    return keep


def _poses_from_xyz_quat(
    p: Path, xyz: NDArray[np.float64], q_xyzw: NDArray[np.float64], lines: NDArray[np.int64]
) -> NDArray[np.float64]:
    with np.errstate(over="ignore", invalid="ignore"):
        norm = np.linalg.norm(q_xyzw, axis=1)
    bad = np.flatnonzero(~((norm >= 1e-9) & (norm < 1e150)))
    if bad.size:
        raise FormatError(
            f"line {lines[bad[0]]} has a zero quaternion (or a huge or non-finite one)",
            source=p,
            field=f"line {lines[bad[0]]}",
            expected="a unit quaternion",
        )
    return se3_from_xyz_quat(xyz, q_xyzw / norm[:, None])


# --------------------------------------------------------------------------- TUM
def read_tum(path: PathLike, *, duplicates: Duplicates = "drop") -> Trajectory:
    """Read a TUM RGB-D trajectory: lines ``t tx ty tz qx qy qz qw`` (seconds, metres).

    Quaternions are scalar-last as in the file and normalised.
    """
    p = _existing(path)
    tab = _read_table(p, 8, "t tx ty tz qx qy qz qw")
    v = tab.values
    keep = _check_times(p, v[:, 0], tab.lines, duplicates)
    poses = _poses_from_xyz_quat(p, v[:, 1:4], v[:, 4:8], tab.lines)
    return Trajectory(v[keep, 0], poses[keep])


def write_tum(path: PathLike, trajectory: Trajectory) -> None:
    """Write a TUM trajectory atomically (``t tx ty tz qx qy qz qw``, w >= 0)."""
    xyz, q = se3_to_xyz_quat(trajectory.poses)
    table = np.column_stack([trajectory.timestamps, xyz, q])
    with atomic_write(path) as fh:
        fh.write("# timestamp tx ty tz qx qy qz qw\n")
        np.savetxt(fh, table, fmt=["%.9f"] + ["%.12g"] * 7)


# --------------------------------------------------------------------------- KITTI
def read_kitti_poses(path: PathLike, timestamps: PathLike | ArrayLike | None = None) -> Trajectory:
    """Read KITTI odometry poses: 12 numbers per line, the 3x4 ``[R | t]`` row-major.

    Parameters
    ----------
    path : str or path
        Poses file (``00.txt``; camera-0 poses ``T_world_cam0``).
    timestamps : path or (N,) array, optional
        A ``times.txt`` file (one time in seconds per line) or the times themselves; default
        ``0, 1, 2, ...`` (the frame index).

    Raises
    ------
    FormatError
        Wrong column counts, a rotation block that is not orthonormal (tolerance 1e-3, far above
        the 1e-6 rounding of published files), or a times count that differs from the poses.
    """
    p = _existing(path)
    tab = _read_table(p, 12, "r11 r12 r13 tx r21 r22 r23 ty r31 r32 r33 tz")
    n = len(tab.values)
    poses = np.zeros((n, 4, 4))
    poses[:, :3, :] = tab.values.reshape(n, 3, 4)
    poses[:, 3, 3] = 1.0
    R = poses[:, :3, :3]
    with np.errstate(over="ignore", invalid="ignore"):
        err = np.abs(R @ np.swapaxes(R, 1, 2) - np.eye(3)).max(axis=(1, 2)) if n else np.zeros(0)
    bad = np.flatnonzero(~(err <= 1e-3))  # NaN / inf entries are not a rotation either
    if bad.size:
        raise FormatError(
            f"line {tab.lines[bad[0]]}: rotation block is not orthonormal (error {err[bad[0]]:.2g})",
            source=p,
            field=f"line {tab.lines[bad[0]]}",
            expected="a 3x4 [R | t] with R a rotation",
        )
    if timestamps is None:
        t = np.arange(n, dtype=np.float64)
        lines = tab.lines
        src = p
    elif isinstance(timestamps, (str, os.PathLike)):
        src = _existing(timestamps)
        ttab = _read_table(src, 1, "time in seconds")
        t = ttab.values[:, 0]
        lines = ttab.lines
    else:
        t = np.asarray(timestamps, dtype=np.float64).ravel()
        lines = np.arange(1, len(t) + 1)
        src = p
    if len(t) != n:
        raise FormatError(
            f"{len(t)} timestamps for {n} poses",
            source=src,
            field="timestamps",
            expected=f"{n} timestamps, one per pose line of {p}",
        )
    keep = _check_times(src, t, lines, "error")
    return Trajectory(t[keep], poses[keep])


def write_kitti_poses(
    path: PathLike, trajectory: Trajectory | ArrayLike, times_path: PathLike | None = None
) -> None:
    """Write KITTI poses atomically (12 numbers per line); optionally the times file too."""
    if isinstance(trajectory, Trajectory):
        poses, t = trajectory.poses, trajectory.timestamps
    else:
        poses = np.asarray(trajectory, dtype=np.float64)
        t = None
        if poses.ndim != 3 or poses.shape[1:] not in ((4, 4), (3, 4)):
            raise InputError(
                f"shape {poses.shape}", field="poses", expected="(N, 4, 4) or (N, 3, 4)"
            )
    with atomic_write(path) as fh:
        np.savetxt(fh, poses[:, :3, :4].reshape(len(poses), 12), fmt="%.12e")
    if times_path is not None:
        if t is None:
            raise InputError(
                "no timestamps to write",
                field="times_path",
                expected="a Trajectory when times_path is given",
            )
        with atomic_write(times_path) as fh:
            np.savetxt(fh, t, fmt="%.9f")


# --------------------------------------------------------------------------- EuRoC
def read_euroc(path: PathLike, *, duplicates: Duplicates = "drop") -> Trajectory:
    """Read a EuRoC MAV ground-truth CSV (``data.csv`` of ``state_groundtruth_estimate0``).

    Columns ``#timestamp [ns], p_RS_R_x [m], p_RS_R_y, p_RS_R_z, q_RS_w [], q_RS_x, q_RS_y,
    q_RS_z, ...`` (velocities and biases after that are ignored). Timestamps are integer
    nanoseconds (converted to seconds); the quaternion is **w first** in this file.
    """
    p = _existing(path)
    tab = _read_table(p, 8, "timestamp[ns], p x y z, q w x y z", delimiter=",", min_cols=True)
    v = tab.values
    try:
        ns = tab.tokens[:, 0].astype(np.int64)
        t = (ns - ns[0]).astype(np.float64) * 1e-9 + ns[0] * 1e-9 if len(ns) else v[:, 0]
    except ValueError:  # not integer nanoseconds: take the float value as nanoseconds
        t = v[:, 0] * 1e-9
    keep = _check_times(p, t, tab.lines, duplicates)
    q_xyzw = v[:, [5, 6, 7, 4]]
    poses = _poses_from_xyz_quat(p, v[:, 1:4], q_xyzw, tab.lines)
    return Trajectory(t[keep], poses[keep])


# --------------------------------------------------------------------------- sniffing
TrajectoryFormat = Literal["auto", "tum", "kitti", "euroc"]


def _sniff(p: Path) -> str:
    with open(p, encoding="utf-8", errors="replace") as fh:
        head = [ln for ln in (fh.readline() for _ in range(50)) if ln]
    if p.suffix.lower() == ".csv" or any("p_RS_R" in ln for ln in head):
        return "euroc"
    for ln in head:
        s = ln.strip()
        if not s or s.startswith("#"):
            continue
        if "," in s:
            return "euroc"
        n = len(s.split())
        if n == 12:
            return "kitti"
        if n == 8:
            return "tum"
        raise FormatError(
            f"first data line has {n} columns",
            source=p,
            field="format",
            expected="8 (TUM), 12 (KITTI) or comma-separated (EuRoC) columns",
        )
    raise FormatError("no data lines", source=p, field="format", expected="a trajectory file")


def read_trajectory(path: PathLike, format: TrajectoryFormat = "auto") -> Trajectory:
    """Read a trajectory in any supported format.

    ``format="auto"`` sniffs it: ``.csv`` or a ``p_RS_R`` header or commas -> EuRoC, 12 columns
    -> KITTI (timestamps = frame index), 8 columns -> TUM.
    """
    p = _existing(path)
    fmt = _sniff(p) if format == "auto" else format
    readers: dict[str, Any] = {"tum": read_tum, "kitti": read_kitti_poses, "euroc": read_euroc}
    if fmt not in readers:
        raise InputError(
            f"unknown format {format!r}", field="format", expected="auto, tum, kitti or euroc"
        )
    log.debug("%s: reading as %s", p, fmt)
    return readers[fmt](p)  # type: ignore[no-any-return]


# --------------------------------------------------------------------------- odometry logs
def read_odometry_log(
    path: PathLike, *, duplicates: Duplicates = "drop"
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """Read a ``time v omega`` odometry log (e.g. UTIAS MRCLAM ``Robot1_Odometry.dat``).

    Returns
    -------
    t : (N,) float64
        Seconds, strictly increasing.
    v : (N,) float64
        Forward speed, m/s.
    omega : (N,) float64
        Turn rate, rad/s (counter-clockwise positive).
    """
    p = _existing(path)
    tab = _read_table(p, 3, "time v omega")
    v = tab.values
    keep = _check_times(p, v[:, 0], tab.lines, duplicates)
    return v[keep, 0].copy(), v[keep, 1].copy(), v[keep, 2].copy()


def looks_like_odometry(path: Path) -> bool:
    """True if the first data line has 3 columns (``time v omega``)."""
    try:
        with open(path, encoding="utf-8", errors="replace") as fh:
            for line in fh:
                s = line.strip()
                if s and not s.startswith("#"):
                    return len(s.replace(",", " ").split()) == 3
    except OSError:
        return False
    return False


#: Domains of a track's numbers (``navkit path record``): positions in metres and odometry
#: speeds either sign (a robot reverses, turns either way), bounded like every navkit number
#: (:data:`navkit.domains.MAX_MAGNITUDE`) so the spline fit's sums stay finite.
COORDINATE = Domain(note="metres, either sign")
SPEED = Domain(note="m/s, either sign")
TURN_RATE = Domain(note="rad/s, either sign")


def load_planar_track(
    path: str | os.PathLike[str], fmt: str = "auto", plane: str = "auto"
) -> tuple[Any, Any, dict[str, Any], str]:
    """Read a trajectory file (TUM, KITTI, EuRoC or a ``time v omega`` odometry log) and map it to
    the ground plane: what ``navkit path record`` stores.

    Returns ``(timestamps (N,), xy (N, 2), frame dict, format used)``.
    """
    from navkit.path.track import clean_track, ground_plane, integrate_odometry, to_plane

    path = Path(path)
    if not path.is_file():
        raise DataNotFoundError(f"{path}: no such trajectory file")
    if fmt == "odometry" or (fmt == "auto" and looks_like_odometry(path)):
        t_raw, v, w = read_odometry_log(path)
        SPEED.check_array(v, "v", source=path, error=FormatError)
        TURN_RATE.check_array(w, "omega", source=path, error=FormatError)
        t_odo, vw = clean_track(t_raw, np.c_[v, w], source=str(path))
        poses = integrate_odometry(t_raw if t_odo is None else t_odo, vw[:, 0], vw[:, 1])
        frame = {
            "kind": "odometry",
            "source": str(path),
            "note": "dead-reckoned from time v omega, start pose (0, 0, 0)",
        }
        COORDINATE.check_array(poses[:, :2], "dead-reckoned x, y", source=path, error=FormatError)
        return t_odo, poses[:, :2], frame, "odometry"
    traj = read_trajectory(path, fmt)  # type: ignore[arg-type]
    COORDINATE.check_array(traj.positions, "position", source=path, error=FormatError)
    t_traj, P = clean_track(traj.timestamps, traj.positions, source=str(path))
    gp = ground_plane(P, plane)
    frame = {**gp.to_dict(), "source": str(path)}
    return t_traj, to_plane(P, gp), frame, (fmt if fmt != "auto" else "detected")
