"""Stage 1 inputs: organising lidar clouds, organised clouds and depth images as scan grids.

Paper 1 works on a grid ``d(alpha_i, beta_j)``. Real data come as

- a spinning-lidar cloud stored point by point (KITTI ``.bin``), whose rings (beams) and
  azimuth columns must be recovered from the points: :func:`cloud_to_grid`;
- an organised cloud (``H x W`` points, e.g. an organised PCD): :func:`organized_to_grid`;
- a depth image and its pinhole camera: :func:`depth_to_grid`.

Every function returns a :class:`ScanGrid`: sensor-frame points ``(n_az, n_el, 3)`` with azimuth
rising along axis 0 and elevation rising along axis 1 (what :func:`detect_obstacles_grid` needs),
and the map between grid cells and the input's points.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from navkit.errors import InputError
from navkit.geometry import R_BODY_FROM_OPTICAL
from navkit.geometry._validate import MAX_COORDINATE_M, check_grid_size, max_grid_cells
from navkit.geometry.angles import atan2
from navkit.jit import kernels_enabled
from navkit.sensors import PinholeCamera

__all__ = ["ScanGrid", "cloud_to_grid", "depth_to_grid", "organized_to_grid"]

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class ScanGrid:
    """Points organised on an azimuth x elevation grid, with the way back to the input.

    Attributes
    ----------
    points : (n_az, n_el, 3) float64
        Sensor-frame points (NaN = empty cell), azimuth rising along axis 0 (counter-clockwise
        seen from +z), elevation rising along axis 1.
    cell_of_point : (N,) int64
        Flat cell index ``i * n_el + j`` of every input point, -1 for points outside the grid
        (no-returns, NaN, unassigned rings). Several input points may share a cell (the grid
        keeps the nearest); they all get that cell's label.
    azimuth : (n_az,) float64 or None
        Azimuth of the grid rows (rad), when known.
    wraps : bool
        The grid covers 360 deg of azimuth (the mesh closes across the seam).
    method : str
        How the grid was recovered (``"order"``, ``"elevation"``, ``"organized"``, ``"depth"``).
    """

    points: NDArray[np.float64]
    cell_of_point: NDArray[np.int64]
    azimuth: NDArray[np.float64] | None
    wraps: bool
    method: str

    @property
    def shape(self) -> tuple[int, int]:
        """``(n_az, n_el)``."""
        return self.points.shape[:2]  # type: ignore[return-value]

    def per_point(self, values: NDArray[Any], fill: int | float = -1) -> NDArray[Any]:
        """Spread a per-cell array ``(n_az, n_el)`` back to the input points ``(N,)``."""
        # one gather from the cells with ``fill`` appended: a point's -1 picks the last element
        ext = np.empty(values.size + 1, dtype=values.dtype)
        ext[:-1], ext[-1] = values.reshape(-1), fill
        return ext[self.cell_of_point]


def _as_cloud(points: ArrayLike, source: str, convert: bool = True) -> NDArray[Any]:
    try:
        P = np.asarray(points)
    except (TypeError, ValueError) as exc:  # pragma: no cover - numpy rarely refuses
        raise InputError(
            f"is not numeric: {exc}", source=source, field="points", expected="(N, 3) floats"
        ) from exc
    if P.dtype.kind not in "fiu":
        raise InputError(
            f"has dtype {P.dtype}",
            source=source,
            field="points",
            expected="a float array (N, 3) or (N, 4)",
        )
    if P.ndim != 2 or P.shape[1] < 3:
        raise InputError(
            f"has shape {P.shape}",
            source=source,
            field="points",
            expected="(N, 3) or (N, >=3) array",
        )
    if P.shape[0] == 0:
        raise InputError("is empty", source=source, field="points", expected="at least one point")
    if not convert and P.dtype in (np.float32, np.float64):
        return P  # the compiled path reads the first three columns itself
    return np.asarray(P[:, :3], dtype=np.float64)


def _rings_by_order(az: NDArray[np.float64]) -> tuple[NDArray[np.int64], float] | None:
    """Rings from the storage order: the unwrapped azimuth advances by 2 pi per ring.

    Returns ``(ring id per point, azimuth step)`` or ``None`` when the order is not a sweep.
    """
    if len(az) < 100:
        return None
    d = np.diff(az)
    # wrap into [-pi, pi) (|d| < 2 pi since the angles are in (-pi, pi]): two masked updates,
    # cheaper than a float modulo over every point
    d[d >= np.pi] -= 2 * np.pi
    d[d < -np.pi] += 2 * np.pi
    step = float(np.median(np.abs(d)))
    if step <= 0:
        return None
    # the sweep's direction: the sign of the median step = whether most steps are positive
    direction = 1.0 if 2 * np.count_nonzero(d > 0) > len(d) else -1.0
    # a sweep: small steps (at least 64 points per turn), nearly all in one direction
    forward = np.mean(direction * d > -0.5 * step)
    if step > 2 * np.pi / 64 or forward < 0.9:
        return None
    unwrapped = direction * np.concatenate([[0.0], np.cumsum(d)])
    # a ring starts where the sweep starts; tolerate small backward jitter with a half-step margin
    ring = np.floor((unwrapped + 0.5 * step) / (2 * np.pi)).astype(np.int64)
    ring -= ring.min()
    n = int(ring.max()) + 1
    if n < 2 or n > 512:
        return None
    return ring, step


def _rings_by_elevation(el: NDArray[np.float64], n_rings: int | None) -> NDArray[np.int64]:
    """Rings by 1-D clustering of the elevation angles (beams at fixed elevations).

    With ``n_rings`` the ``n_rings - 1`` widest gaps in the sorted elevations split the rings;
    otherwise every gap wider than 20 times the median gap does, and clusters holding less than
    1 % of the median cluster size are dropped (ring -1).
    """
    order = np.argsort(el, kind="stable")
    s = el[order]
    gaps = np.diff(s)
    if n_rings is not None:
        if n_rings < 1 or n_rings > len(s):
            raise InputError(f"= {n_rings}", field="n_rings", expected=f"1 .. {len(s)}")
        cut = (
            np.sort(np.argpartition(gaps, -(n_rings - 1))[-(n_rings - 1) :])
            if n_rings > 1
            else np.array([], dtype=np.int64)
        )
    else:
        pos = gaps[gaps > 0]
        thr = 20 * float(np.median(pos)) if pos.size else np.inf
        thr = max(thr, 1e-4)
        cut = np.flatnonzero(gaps > thr)
    ring_sorted = np.zeros(len(s), dtype=np.int64)
    ring_sorted[cut + 1] = 1
    ring_sorted = np.cumsum(ring_sorted)
    ring = np.empty_like(ring_sorted)
    ring[order] = ring_sorted
    if n_rings is None:
        counts = np.bincount(ring)
        small = counts < 0.01 * np.median(counts)
        if small.any():
            lut = np.cumsum(~small) - 1
            lut[small] = -1
            ring = lut[ring]
    return ring


_FAR = MAX_COORDINATE_M  # metres: a "return" beyond it is a corrupt value, a no-return


def _check_count(value: int | None, name: str, low: int) -> None:
    """An optional size argument: an integer from ``low`` to the grid-size bound (checked before
    anything is allocated from it)."""
    if value is None:
        return
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)):
        raise InputError(f"= {value!r}", field=name, expected=f"an integer >= {low}")
    limit = max_grid_cells()
    if not low <= value <= limit:
        raise InputError(
            f"= {value}",
            field=name,
            expected=f"an integer from {low} to {limit} (the grid-size bound; the environment "
            "variable NAVKIT_MAX_GRID_CELLS raises it)",
        )


def cloud_to_grid(
    points: ArrayLike,
    *,
    n_rings: int | None = None,
    n_columns: int | None = None,
    ring_method: str = "auto",
    source: str = "points",
) -> ScanGrid:
    """Recover the scan grid of a spinning-lidar cloud (any beam count, any storage order).

    Parameters
    ----------
    points : (N, 3) or (N, >=3) float
        Sensor-frame points (extra columns such as intensity are ignored). Points at exactly
        ``(0, 0, 0)``, with a NaN or farther than 1e9 m are no-returns (several datasets store
        them so).
    n_rings : int, optional
        Number of beams; needed only by ``ring_method="elevation"`` when the elevations are not
        cleanly separated.
    n_columns : int, optional
        Azimuth columns; by default ``round(2 pi / step)`` with ``step`` the median azimuth step
        between consecutive points of a ring (robust to dropped returns).
    ring_method : {"auto", "order", "elevation"}
        ``"order"``: rings from the storage order (the azimuth sweeps 2 pi per ring, as in KITTI,
        whose beams are not at a fixed elevation: the HDL-64E lasers have offset origins);
        ``"elevation"``: rings by clustering the elevation angles (any order);
        ``"auto"``: ``"order"`` when the storage order is a coherent sweep, else ``"elevation"``.

    Returns
    -------
    ScanGrid
        Rings sorted by rising mean elevation; azimuth columns rising counter-clockwise from
        -pi, centred on the sensor's firing azimuths (their phase is estimated); each cell keeps
        its nearest point.

    With the compiled kernels (:mod:`navkit.jit`) the steps run in
    :mod:`navkit.obstacles._kernels_grid`; the NumPy code below is their twin: the same grid.
    """
    compiled = kernels_enabled()
    if ring_method not in ("auto", "order", "elevation"):
        raise InputError(
            f"= {ring_method!r}", field="ring_method", expected="'auto', 'order' or 'elevation'"
        )
    _check_count(n_columns, "n_columns", 2)
    _check_count(n_rings, "n_rings", 1)
    P = _as_cloud(points, source, convert=not compiled)
    if compiled and ring_method in ("auto", "order") and n_columns is None:
        fast = _grid_by_order_compiled(P, source)
        if fast is not None:
            return fast
    N = len(P)
    far = np.abs(P) >= _FAR  # NaN compares False
    if far.any():  # a "return" beyond 1e9 m is a corrupt value, not a point (kernels and twin)
        P = np.where(far.any(axis=1, keepdims=True), np.nan, P)
    if compiled:  # validity, the valid rows as float64 and their horizontal range: one pass
        from navkit.obstacles import _kernels_grid as _kernels

        Q, idx, rh = _kernels.cloud_prep_kernel(P)
    else:
        x0, y0, z0 = P[:, 0], P[:, 1], P[:, 2]
        # column by column: reductions along a length-3 axis are slow in NumPy
        ok = (
            np.isfinite(x0)
            & np.isfinite(y0)
            & np.isfinite(z0)
            & ((x0 != 0) | (y0 != 0) | (z0 != 0))
        )
        all_ok = bool(ok.all())
        idx = np.arange(N) if all_ok else np.flatnonzero(ok)
    if idx.size < 4:
        raise InputError(
            f"has {idx.size} valid points",
            source=source,
            field="points",
            expected="at least 4 points that are not NaN or (0, 0, 0)",
        )
    if not compiled:
        Q = P if all_ok else P[idx]
        rh = np.hypot(Q[:, 0], Q[:, 1])
    # the azimuth with one fixed arithmetic (navkit.geometry.angles: the same bits on every
    # machine and in the kernel; NumPy's arctan2 differs between machines)
    if compiled:
        from navkit.geometry._kernels_math import atan2_kernel

        qy, qx = np.ascontiguousarray(Q[:, 1]), np.ascontiguousarray(Q[:, 0])
        az = atan2_kernel(qy, qx, np.empty(len(Q)))
    else:
        az = atan2(Q[:, 1], Q[:, 0])
    if compiled and ring_method in ("auto", "order"):
        found, ring_o, step_o = _kernels.rings_by_order_kernel(az)
        by_order = (ring_o, float(step_o)) if found else None
    else:
        by_order = _rings_by_order(az) if ring_method in ("auto", "order") else None
    if ring_method == "order" and by_order is None:
        raise InputError(
            "the storage order is not a lidar sweep",
            source=source,
            field="points",
            expected="points stored ring by ring (or use ring_method='elevation')",
        )
    if by_order is not None:
        ring, step = by_order
        method = "order"
    else:
        with np.errstate(invalid="ignore", divide="ignore"):
            ring = _rings_by_elevation(np.arctan2(Q[:, 2], rh), n_rings)
        method = "elevation"
        step = 0.0
    if compiled and method == "order" and n_columns is None:
        # the rings come from the order (all >= 0): columns and cells in two kernels
        n_columns = max(3, round(2 * np.pi / step))
        xs = (az[:: max(1, len(az) // 20000)] + np.pi) / (2 * np.pi) * n_columns
        frac = 2 * np.pi * (xs % 1.0)
        phase = float(np.arctan2(np.sin(frac).mean(), np.cos(frac).mean()) / (2 * np.pi))
        cell, n_el = _kernels.grid_cells_kernel(Q, rh, az, ring, n_columns, phase)
        check_grid_size((n_columns, n_el), setting="n_columns", source=source)
        grid = _kernels.grid_fill_kernel(Q, rh, cell, n_columns * n_el)
        return _finish_grid(grid, idx, cell, N, n_columns, n_el, phase, method)
    keep = ring >= 0
    if not keep.all():
        idx, Q, az, ring, rh = idx[keep], Q[keep], az[keep], ring[keep], rh[keep]
    with np.errstate(invalid="ignore", divide="ignore"):
        tan_el = Q[:, 2] / np.maximum(rh, 1e-9)  # monotone in the elevation: enough to order rings
    n_r = int(ring.max()) + 1
    # order rings by rising mean elevation
    counts = np.bincount(ring, minlength=n_r)
    present = counts > 0
    mean_el = np.bincount(ring, weights=tan_el, minlength=n_r) / np.maximum(counts, 1)
    rank = np.argsort(np.where(present, mean_el, np.inf), kind="stable")
    lut = np.empty(n_r, dtype=np.int64)
    lut[rank] = np.arange(n_r)
    j = lut[ring]
    n_el = int(present.sum())
    if n_columns is None:
        if step <= 0:
            # per ring, the azimuth step between neighbours in azimuth order
            o = np.lexsort((az, ring))
            da = np.diff(az[o])
            same = ring[o][1:] == ring[o][:-1]
            da = da[same & (da > 0)]
            step = float(np.median(da)) if da.size else 2 * np.pi / 360
        n_columns = max(3, round(2 * np.pi / step))
    if n_columns < 2:
        raise InputError(f"= {n_columns}", field="n_columns", expected="an integer >= 2")
    check_grid_size((n_columns, n_el), setting="n_columns", source=source)
    # columns centred on the sensor's firing azimuths: their phase is the circular mean of the
    # fractional column positions (a sensor fires at a fixed lattice of azimuths)
    x = (az + np.pi) / (2 * np.pi) * n_columns
    frac = 2 * np.pi * (x[:: max(1, len(x) // 20000)] % 1.0)  # a subsample is plenty
    phase = float(
        np.arctan2(np.sin(frac).mean(), np.cos(frac).mean()) / (2 * np.pi)
    )  # in (-1/2, 1/2]
    i = np.floor(x - phase + 0.5).astype(np.int64) % n_columns
    cell = i * n_el + j
    # the nearest point of each cell represents it: scatter every point's index, then let points
    # nearer than their cell's current winner overwrite it until none is (a few rounds: as many
    # as the largest number of points in one cell) - no sort
    if compiled:
        grid = _kernels.grid_fill_kernel(Q, rh, cell, n_columns * n_el)
    else:
        r = np.sqrt(rh * rh + Q[:, 2] * Q[:, 2])
        win = np.full(n_columns * n_el, -1, dtype=np.intp)
        win[cell] = np.arange(len(cell))
        while True:
            better = np.flatnonzero(r < r[win[cell]])
            if better.size == 0:
                break
            win[cell[better]] = better
        # gather with a NaN row appended for the empty cells (win = -1 picks the last row): one
        # contiguous ``take`` is ~3x cheaper than a masked fancy-indexed row assignment
        grid = np.concatenate([Q, np.full((1, 3), np.nan)]).take(win, axis=0)
    return _finish_grid(grid, idx, cell, N, n_columns, n_el, phase, method)


def _grid_by_order_compiled(P: NDArray[Any], source: str) -> ScanGrid | None:
    """:func:`cloud_to_grid` with rings from the storage order, compiled: five kernels over
    caller-provided arrays (:mod:`navkit.obstacles._buffers`), the azimuth by
    :func:`navkit.geometry._kernels_math.atan2_kernel` (the twin's :func:`navkit.geometry.angles.atan2`,
    bit for bit). ``None`` when the order is not a sweep (the caller then
    takes the general path). The same grid as the twin, bit for bit: the twin's ``hypot`` per
    point only enters comparisons, which are decided exactly without it (:func:`_ring_lut`,
    :func:`navkit.obstacles._kernels_grid.grid_order_fill_kernel`)."""
    from navkit.geometry._kernels_math import atan2_kernel
    from navkit.obstacles import _kernels_grid as _kernels
    from navkit.obstacles._buffers import arena, cached_work

    N = len(P)
    cap = -(-N // 65536) * 65536  # work arrays reused across clouds of about the same size
    (work_f, work_i, sums, abs_sums, counts) = cached_work(
        ("cloud_to_grid", cap),
        lambda: arena(
            [
                ((7, cap), np.float64),
                ((2, cap), np.int64),
                ((513,), np.float64),
                ((513,), np.float64),
                ((513,), np.int64),
            ]
        ),
    )
    qx, qy, qz, az_buf, d, ad, tmp = work_f
    idx, ring = work_i
    m = _kernels.cloud_valid_kernel(P, _FAR, qx, qy, qz, idx)
    if m < 4:
        raise InputError(
            f"has {m} valid points",
            source=source,
            field="points",
            expected="at least 4 points that are not NaN or (0, 0, 0)",
        )
    az = atan2_kernel(qy[:m], qx[:m], az_buf[:m])
    found, step, n_r, lo = _kernels.rings_order_kernel(
        az, qx, qy, qz, d, ad, tmp, ring, sums, abs_sums, counts
    )
    if not found:
        return None
    n_columns = max(3, round(2 * np.pi / step))
    sub = max(1, m // 20000)
    if _libm_sin_cos():  # sin and cos in one kernel, their means NumPy's (as the twin's)
        k = _kernels.phase_sin_cos_kernel(az, sub, n_columns, d, ad)
        mean_sin, mean_cos = d[:k].mean(), ad[:k].mean()
    else:  # NumPy's sin / cos are not libm's here: theirs, as the twin
        frac = tmp[: _kernels.phase_fractions_kernel(az, sub, n_columns, tmp)]
        mean_sin, mean_cos = np.sin(frac).mean(), np.cos(frac).mean()
    phase = float(np.arctan2(mean_sin, mean_cos) / (2 * np.pi))
    lut, n_el = _ring_lut(
        qx[:m], qy[:m], qz[:m], ring[:m], lo, sums[:n_r], abs_sums[:n_r], counts[:n_r]
    )
    check_grid_size((n_columns, n_el), setting="n_columns", source=source)
    n_cells = n_columns * n_el
    (win, best) = cached_work(
        ("cloud_to_grid cells", n_cells, N < 2**31),
        lambda: arena(
            [((n_cells,), np.int32 if N < 2**31 else np.int64), ((n_cells,), np.float64)]
        ),
    )
    grid, cell_of_point = arena([((n_cells, 3), np.float64), ((N,), np.int64)])
    _kernels.grid_order_fill_kernel(
        qx,
        qy,
        qz,
        az,
        idx,
        ring,
        lo,
        lut,
        n_el,
        n_columns,
        phase,
        win,
        best,
        tmp,
        grid,
        cell_of_point,
    )
    azimuth = -np.pi + (np.arange(n_columns) + phase) * 2 * np.pi / n_columns
    log.debug("cloud_to_grid: %d points -> %d x %d grid by order", N, n_columns, n_el)
    return ScanGrid(grid.reshape(n_columns, n_el, 3), cell_of_point, azimuth, True, "order")


def _ring_lut(
    qx: NDArray[np.float64],
    qy: NDArray[np.float64],
    qz: NDArray[np.float64],
    ring: NDArray[np.int64],
    lo: int,
    sums: NDArray[np.float64],
    abs_sums: NDArray[np.float64],
    counts: NDArray[np.int64],
) -> tuple[NDArray[np.int64], int]:
    """The elevation index of every ring ``ring - lo`` (rings ranked by rising mean ``z / r_h``,
    stable, empty rings last, as the twin ranks them) and the number of rings with points.

    The ranking comes from the kernel's sums of ``z / max(sqrt(x^2 + y^2), 1e-9)`` (no
    ``hypot`` per point) when it is certain: sorted, every two neighbouring keys farther apart
    than twice the sum of their error bounds, ``(8 + 4 count) 2^-52`` times the mean magnitude
    (a few eps per value for ``sqrt`` instead of ``hypot`` plus the rounding of both sums, in
    any order, with a wide margin). Otherwise the twin's keys are computed (``np.hypot``,
    ``bincount`` in point order): the ranks are the twin's either way."""
    n_r = len(counts)
    present = counts > 0
    n_el = int(present.sum())
    cnt = np.maximum(counts, 1)
    key = np.where(present, sums / cnt, np.inf)
    rank = np.argsort(key, kind="stable")
    err = (8 + 4 * counts) * 2.0**-52 * abs_sums / cnt
    a, b = rank[: n_el - 1], rank[1:n_el]
    if not np.all(key[b] - key[a] > 2 * (err[a] + err[b])):  # too close to tell: the twin's
        tan_el = qz / np.maximum(np.hypot(qx, qy), 1e-9)
        mean_el = np.bincount(ring - lo, weights=tan_el, minlength=n_r) / cnt
        rank = np.argsort(np.where(present, mean_el, np.inf), kind="stable")
    lut = np.empty(n_r, dtype=np.int64)
    lut[rank] = np.arange(n_r)
    return lut, n_el


_LIBM_SIN_COS: list[bool] = []


def _libm_sin_cos() -> bool:
    """Whether NumPy's float64 ``sin`` and ``cos`` give libm's results (``math.sin`` /
    ``math.cos`` in a kernel) on this machine: checked once per process on 4,096 values of
    ``[0, 2 pi)``. NumPy calls libm for them on the machines measured; a NumPy build with its
    own SIMD versions keeps NumPy's in the phase (the twin's values either way)."""
    if not _LIBM_SIN_COS:
        from navkit.obstacles import _kernels_grid as _kernels

        az = np.random.default_rng(12).uniform(-np.pi, np.pi, 4096)
        az[:64] = np.linspace(-np.pi, np.pi, 64, endpoint=False)
        s, c = np.empty_like(az), np.empty_like(az)
        _kernels.phase_sin_cos_kernel(az, 1, 1, s, c)  # one column: the fractions of a turn
        frac = 2 * np.pi * (((az + np.pi) / (2 * np.pi) * 1) % 1.0)  # the same values
        _LIBM_SIN_COS.append(
            bool(np.array_equal(s, np.sin(frac)) and np.array_equal(c, np.cos(frac)))
        )
    return _LIBM_SIN_COS[0]


def _finish_grid(
    grid: NDArray[np.float64],
    idx: NDArray[np.int64],
    cell: NDArray[np.int64],
    N: int,
    n_columns: int,
    n_el: int,
    phase: float,
    method: str,
) -> ScanGrid:
    cell_of_point = np.full(N, -1, dtype=np.int64)
    cell_of_point[idx] = cell
    azimuth = -np.pi + (np.arange(n_columns) + phase) * 2 * np.pi / n_columns
    log.debug("cloud_to_grid: %d points -> %d x %d grid by %s", N, n_columns, n_el, method)
    return ScanGrid(grid.reshape(n_columns, n_el, 3), cell_of_point, azimuth, True, method)


def organized_to_grid(points: ArrayLike, *, source: str = "points") -> ScanGrid:
    """An organised cloud ``(H, W, 3)`` (sensor frame) as a scan grid, whatever its layout.

    The axis along which the azimuth changes most becomes the azimuth axis, and both axes are
    flipped as needed so that azimuth and elevation rise (an image-like layout - rows top to
    bottom, columns left to right - is transposed and flipped). NaN or ``(0, 0, 0)`` = no return.
    """
    try:
        G = np.asarray(points, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise InputError(
            f"is not numeric: {exc}", source=source, field="points", expected="(H, W, 3) floats"
        ) from exc
    if G.ndim != 3 or G.shape[2] < 3 or G.shape[0] < 2 or G.shape[1] < 2:
        raise InputError(
            f"has shape {G.shape}",
            source=source,
            field="points",
            expected="an organised (H, W, 3) cloud, H, W >= 2",
        )
    G = G[..., :3].copy()
    bad = ~np.all(np.isfinite(G), axis=-1) | np.all(G == 0.0, axis=-1)
    G[bad] = np.nan
    if bad.all():
        raise InputError(
            "has no valid point", source=source, field="points", expected="at least one return"
        )
    az = np.arctan2(G[..., 1], G[..., 0])
    el = np.arctan2(G[..., 2], np.hypot(G[..., 0], G[..., 1]))

    def trend(a: NDArray[np.float64], axis: int) -> float:
        d = np.diff(a, axis=axis)
        d = (d + np.pi) % (2 * np.pi) - np.pi
        return float(np.nanmedian(d)) if np.isfinite(d).any() else 0.0

    cell = np.arange(G.shape[0] * G.shape[1]).reshape(G.shape[:2])
    if abs(trend(az, 0)) < abs(trend(az, 1)):  # azimuth changes along columns: transpose
        G, az, el, cell = G.transpose(1, 0, 2), az.T, el.T, cell.T
    if trend(az, 0) < 0:
        G, az, el, cell = G[::-1], az[::-1], el[::-1], cell[::-1]
    if trend(el, 1) < 0:
        G, az, el, cell = G[:, ::-1], az[:, ::-1], el[:, ::-1], cell[:, ::-1]
    G = np.ascontiguousarray(G)
    n_el = G.shape[1]
    # input point k sits in grid cell (i, j) where cell[i, j] == k
    cell_of_point = np.empty(cell.size, dtype=np.int64)
    ii, jj = np.indices(cell.shape)
    cell_of_point[cell.ravel()] = (ii * n_el + jj).ravel()
    cell_of_point[bad.ravel()] = -1
    row_az = (
        np.nanmedian(np.where(np.isfinite(az), az, np.nan), axis=1)
        if np.isfinite(az).any(axis=1).all()
        else None
    )
    span = np.ptp(row_az) if row_az is not None else 0.0
    wraps = bool(row_az is not None and span > 2 * math.pi * (1 - 2.0 / len(row_az)))
    return ScanGrid(G, cell_of_point, row_az, wraps, "organized")


def depth_to_grid(depth: ArrayLike, camera: PinholeCamera, *, source: str = "depth") -> ScanGrid:
    """A depth image (metres, NaN / 0 invalid) as a scan grid in the sensor frame (x fwd, y left, z up).

    Pixels are back-projected with the pinhole model and turned from the OpenCV optical frame to
    the sensor's body-like axes (:data:`navkit.geometry.R_BODY_FROM_OPTICAL`); image columns right
    to left become rising azimuth, rows bottom to top rising elevation.
    """
    try:
        D = np.asarray(depth, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise InputError(
            f"is not numeric: {exc}", source=source, field="depth", expected="(H, W) metres"
        ) from exc
    if D.ndim != 2 or D.shape != (camera.height, camera.width):
        raise InputError(
            f"has shape {D.shape}",
            source=source,
            field="depth",
            expected=f"(H, W) = ({camera.height}, {camera.width}) as the camera",
        )
    D = np.where(np.isfinite(D) & (D > 0), D, np.nan)
    if not np.isfinite(D).any():
        raise InputError(
            "has no valid depth", source=source, field="depth", expected="some depth > 0"
        )
    P = camera.backproject(D) @ R_BODY_FROM_OPTICAL.T  # (H, W, 3) x forward, y left, z up
    H, W = D.shape
    G = np.ascontiguousarray(P[::-1, ::-1].transpose(1, 0, 2))  # grid[i, j] = P[H-1-j, W-1-i]
    jj, ii = np.meshgrid(np.arange(H), np.arange(W))
    pix = (H - 1 - jj) * W + (W - 1 - ii)  # input pixel of grid cell (i, j)
    cell_of_point = np.empty(H * W, dtype=np.int64)
    cell_of_point[pix.ravel()] = (ii * H + jj).ravel()
    cell_of_point[~np.isfinite(D).ravel()] = -1
    return ScanGrid(G, cell_of_point, None, False, "depth")
