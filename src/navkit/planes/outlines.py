"""Labels, inliers and outlines of the organised plane extraction (:mod:`navkit.planes.extract`,
step 6): the label image with each segment's inliers, each plane's 2D frame, and the outline of
every segment rasterised in its plane. Each function runs the compiled kernel
(:mod:`navkit.planes._kernels_outline`) or its NumPy twin, the same bits either way."""

from __future__ import annotations

import logging

import cv2
import numpy as np
from numpy.typing import NDArray

from navkit.geometry.fitting import Plane
from navkit.planes.moments import (
    _Border,
    _outline_kernels,
    _Patches,
    _sample_stride,
    _stride_masks,
)
from navkit.planes.segments import outline_from_points, outline_of_closed

log = logging.getLogger(__name__)


def _label_image_numpy(
    valid: NDArray[np.bool_],
    lab_cell: NDArray[np.int64],
    ids: NDArray[np.int64],
    mixed: NDArray[np.bool_],
    bd: _Border,
    new_id: NDArray[np.int64],
    segmap: NDArray[np.int64],
    H: int,
    W: int,
) -> tuple[NDArray[np.int64], list[NDArray[np.int64]]]:
    """NumPy oracle of :func:`navkit.planes._kernels_outline.label_image`: the label image
    ``(H, W)`` and each segment's inliers in raster order."""
    hc, wc = lab_cell.shape
    c = valid.shape[0] // hc
    K = int(new_id.max()) + 1
    # label image (8- or 16-bit): wholesale patches, then the pixels of the mixed patches
    small = np.int8 if K < 127 else np.int16 if K < 32767 else np.int32
    lab4 = np.where(
        valid.reshape(hc, c, wc, c), lab_cell.astype(small)[:, None, :, None], small(-1)
    )
    if mixed.any():
        mi, mj = np.divmod(ids[mixed], wc)
        lab4[mi, :, mj, :] = new_id[bd.label[mixed].astype(np.int64) + 1]
    Hc, Wc = hc * c, wc * c
    if (Hc, Wc) == (H, W):
        lab_small = lab4.reshape(H, W)
    else:
        lab_small = np.full((H, W), -1, small)
        lab_small[:Hc, :Wc] = lab4.reshape(Hc, Wc)
    # inliers in raster order per plane: the label image's rows a plane can reach - the patch
    # rows of its region and one more on each side (a refined border patch next to it) -
    # searched for its label; ~2x faster than one stable sort of the whole label image
    in_row = (segmap[None] == np.arange(K)[:, None, None]).any(axis=2)  # (K, hc)
    row_lo = np.maximum(np.argmax(in_row, axis=1) - 1, 0) * c * W
    row_hi = np.minimum(hc - np.argmax(in_row[:, ::-1], axis=1) + 1, hc) * c * W
    flat_lab = lab_small.ravel()
    inliers = [np.flatnonzero(flat_lab[row_lo[k] : row_hi[k]] == k) + row_lo[k] for k in range(K)]
    return lab_small.astype(np.int64), inliers


def _plane_frames(planes: list[Plane]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Axes ``(K, 2, 3)`` of every plane's 2D frame and the frame's origin in those axes
    ``(K, 2)``: :func:`navkit.planes.segments.plane_frame` (``Plane.basis``) for all planes at
    once (the same frames to the last bits of the norm)."""
    K = len(planes)
    n = np.array([p.normal for p in planes], np.float64).reshape(K, 3)
    rho = np.array([p.rho for p in planes], np.float64)
    use_x = np.abs(n[:, 0]) < 0.9  # the world x axis projected, else the y axis
    ref = np.zeros((K, 3))
    ref[use_x, 0] = 1.0
    ref[~use_x, 1] = 1.0
    u = ref - np.where(use_x, n[:, 0], n[:, 1])[:, None] * n
    u /= np.sqrt(np.einsum("ki,ki->k", u, u))[:, None]
    # n x u written out: numpy.cross's products and differences in its order (the same bits;
    # ~20 us a frame less than its axis handling)
    v = np.empty_like(u)
    v[:, 0] = n[:, 1] * u[:, 2] - n[:, 2] * u[:, 1]
    v[:, 1] = n[:, 2] * u[:, 0] - n[:, 0] * u[:, 2]
    v[:, 2] = n[:, 0] * u[:, 1] - n[:, 1] * u[:, 0]
    axes = np.stack([u, v], axis=1)
    off = np.einsum("kai,ki->ka", axes, rho[:, None] * n)
    return axes, off


def _outlines(
    pt: _Patches,
    labels: NDArray[np.signedinteger],
    wholesale: NDArray[np.bool_],
    segmap: NDArray[np.int64],
    points: NDArray[np.floating],
    point_region: NDArray[np.signedinteger],
    new_id: NDArray[np.int64],
    planes: list[Plane],
    c: int,
    cell: float,
    compiled: bool = False,
) -> list[tuple[NDArray[np.float64], float]]:
    """Step 6, outlines: each plane's wholesale patches as quadrilaterals, its other pixels as
    points, rasterised in the plane (:func:`navkit.planes.segments.outline_from_points`).

    Each corner of a patch's quadrilateral is its lattice corner - pixel ``(i c, j c)`` for the
    top left, ``(i c, (j + 1) c)`` for the top right ..., shared with the neighbours, so that
    quadrilaterals tile a region without gaps - when that pixel is an inlier of the plane, else
    the patch's own corner pixel (``(i c, j c + c - 1)`` ...: at a region's edge the outline then
    stops one pixel short of the lattice). A quadrilateral stands for its pixels only where they
    sample the plane densely, i.e. as the pixels themselves would fill the raster: pixel spacing
    along each side (``side / c``) at most two raster cells (the 3 x 3 closing bridges one empty
    cell). Sparser patches (far, grazing: up to the horizon of an infinite floor) and patches
    with a corner off the plane are rasterised pixel by pixel (every ``t``-th row / column,
    :func:`_sample_stride`), as before the quadrilaterals.

    The corners (projected with each patch's plane axes), the sampled pixels and their grouping
    by plane are computed for all planes at once; only the projection of a plane's points (its
    axes as scalars: gathering the axes per point is ~8x slower) and the rasterisation run per
    plane. ``segmap (hc, wc)`` is the segment of each patch's region (``-1`` = none), the labels
    are segment indices, ``points (3, N)`` the sampled pixels of the mixed patches,
    ``point_region (N,)`` their regions and ``new_id`` the segment of region + 1.
    """
    hc, wc = segmap.shape
    K = len(planes)
    axes, off = _plane_frames(planes)
    if compiled:  # quadrilaterals, strides, grouping and projection in one kernel, same floats
        uv_all, cuts, q_used, ucuts = _outline_kernels().outline_samples(
            pt.P, pt.valid, labels, wholesale, segmap, pt.M, points, point_region, new_id, axes,
            off, c, cell,
        )  # fmt: skip
        step = np.maximum(1, np.diff(cuts) // 40_000)  # at most ~40k points per plane
        return _outlines_compiled(uv_all, cuts, step, q_used, ucuts, cell)

    def project(xyz: list[NDArray], k: NDArray[np.int64]) -> NDArray[np.float64]:
        """``(..., 2)`` in-plane coordinates of points ``xyz`` (3 arrays) in segments ``k``."""
        A, o = axes[k], off[k]
        return np.stack(
            [
                xyz[0] * A[..., a, 0] + xyz[1] * A[..., a, 1] + xyz[2] * A[..., a, 2] - o[..., a]
                for a in range(2)
            ],
            axis=-1,
        )

    # wholesale patches of kept planes, grouped by segment (raster order within one)
    cells = np.flatnonzero(wholesale.ravel() & (segmap.ravel() >= 0))
    cells = cells[np.argsort(segmap.ravel()[cells], kind="stable")]
    qseg = segmap.ravel()[cells]
    ii, jj = np.divmod(cells, wc)
    # corners in order around the patch: lattice, else the patch's own corner pixel
    r0, q0 = ii * c, jj * c
    lat_r = np.minimum(np.stack([r0, r0, r0 + c, r0 + c], axis=1), hc * c - 1)
    lat_q = np.minimum(np.stack([q0, q0 + c, q0 + c, q0], axis=1), wc * c - 1)
    own_r = np.stack([r0, r0, r0 + c - 1, r0 + c - 1], axis=1)
    own_q = np.stack([q0, q0 + c - 1, q0 + c - 1, q0], axis=1)
    lat_ok = labels[lat_r, lat_q] == qseg[:, None]
    cr, cq = np.where(lat_ok, lat_r, own_r), np.where(lat_ok, lat_q, own_q)
    quads = project([pt.P[cr, cq, a] for a in range(3)], qseg[:, None])  # (Q, 4, 2)
    edge = np.diff(quads, axis=1, append=quads[:, :1])  # (Q, 4, 2) the four sides
    longest = np.sqrt(np.max(edge[..., 0] * edge[..., 0] + edge[..., 1] * edge[..., 1], axis=1))
    use = np.all(lat_ok | (labels[own_r, own_q] == qseg[:, None]), axis=1)
    use &= longest <= 2.0 * cell * c
    qcuts = np.searchsorted(qseg, np.arange(K + 1))
    # points: the sampled pixels of the mixed patches, then of the wholesale patches not used
    # as quadrilaterals (every t-th row / column), grouped by segment
    pseg = new_id[np.asarray(point_region, np.int64) + 1]
    xyz = [points[a] for a in range(3)]
    if not use.all():
        bi, bj = ii[~use], jj[~use]
        t = _sample_stride(pt.M[bi * wc + bj], c, cell)
        vb = pt.valid.reshape(hc, c, wc, c)[bi, :, bj, :]
        vb &= _stride_masks(c)[t].reshape(-1, c, c)
        b, r, q = np.nonzero(vb)
        Pb = pt.P[bi[b] * c + r, bj[b] * c + q]  # (K, 3): only the sampled pixels
        xyz = [np.concatenate([xyz[a], Pb[:, a]]) for a in range(3)]
        pseg = np.concatenate([pseg, qseg[~use][b]])
    # stable sort by segment: NumPy's radix sort for 16-bit keys (K < 32767 segments)
    order = np.argsort(pseg.astype(np.int16 if K < 32767 else np.int64), kind="stable")
    pcuts = np.searchsorted(pseg[order], np.arange(K + 1))
    xyz = [x[order] for x in xyz]
    out = []
    for k in range(K):
        n_k = pcuts[k + 1] - pcuts[k]
        pk = slice(pcuts[k], pcuts[k + 1], max(1, n_k // 40_000))  # at most ~40k points
        # one segment's points with scalar axes: ~8x faster than gathering axes per point
        x, y, z = (a[pk] for a in xyz)
        A, o = axes[k], off[k]
        uv = np.stack([x * A[a, 0] + y * A[a, 1] + z * A[a, 2] - o[a] for a in range(2)], axis=1)
        ql, qh = qcuts[k], qcuts[k + 1]
        out.append(outline_from_points(uv, cell, quads=quads[ql:qh][use[ql:qh]]))
    return out


def _outlines_compiled(
    uv: NDArray[np.float64],
    cuts: NDArray[np.int64],
    step: NDArray[np.int64],
    quads: NDArray[np.float64],
    qcuts: NDArray[np.int64],
    cell: float,
) -> list[tuple[NDArray[np.float64], float]]:
    """``outline_from_points(uv[cuts[k]:cuts[k + 1]:step[k]], cell, quads=quads[qcuts[k]:
    qcuts[k + 1]])`` for every segment ``k``, the same outlines and areas: the rasters of all
    segments drawn in one compiled pass
    (:func:`navkit.planes._kernels_outline.outline_rasters`), per segment OpenCV's polygon fill,
    the closings of all rasters in one compiled pass
    (:func:`navkit.planes._kernels_outline.close_rasters`, OpenCV's cells) and per segment the
    contour (``segments.outline_of_closed``)."""
    buf, start, shape, lo, status, qint, qfin = _outline_kernels().outline_rasters(
        np.ascontiguousarray(uv, dtype=np.float64).reshape(-1, 2),
        cuts,
        step,
        np.ascontiguousarray(quads, dtype=np.float64).reshape(-1, 4, 2),
        qcuts,
        float(cell),
    )
    K = len(cuts) - 1
    grids = []
    for k in range(K):
        w, h = int(shape[k, 0]), int(shape[k, 1])
        grid = buf[start[k] : start[k] + w * h].reshape(h, w)
        grids.append(grid)
        if status[k] == 0:
            qk = qint[qcuts[k] : qcuts[k + 1]][qfin[qcuts[k] : qcuts[k + 1]]]
            if len(qk):
                cv2.fillPoly(grid, list(qk), 1, cv2.LINE_8, 4)
    covered = _outline_kernels().close_rasters(buf, start, shape, status)  # OpenCV's closing
    out = []
    for k in range(K):
        if status[k] == 1:  # fewer than 3 points and corners
            out.append((np.zeros((0, 2)), 0.0))
        elif status[k] == 2:  # a huge raster: outline_from_points coarsens it
            uv_k = uv[cuts[k] : cuts[k + 1] : step[k]]
            out.append(outline_from_points(uv_k, cell, quads=quads[qcuts[k] : qcuts[k + 1]]))
        else:
            area = float(covered[k]) * cell * cell
            out.append(outline_of_closed(grids[k], area, lo[k], cell))
    return out
