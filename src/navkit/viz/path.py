"""Figures of the path memory (paper 4): the recorded path and the simulated returns (fig. 4)."""

from __future__ import annotations

import os
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from navkit.io.atomic import atomic_path

if TYPE_CHECKING:
    from navkit.path import ApproximationResult, PathSpline
    from navkit.sim.return_sim import ReturnSimResult

__all__ = ["plot_record", "plot_returns"]


def _figure(ncols: int = 1, width: float = 7.0):  # type: ignore[no-untyped-def]
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, ncols, figsize=(width * ncols, width * 0.85), squeeze=False)
    return plt, fig, axes[0]


def _spline_xy(spline: PathSpline) -> NDArray[np.float64]:
    if spline.n_segments == 0 or spline.total_length <= 0:
        return np.zeros((0, 2))
    step = max(spline.total_length / 20000.0, 1e-3)
    return spline.sample(step)[1]


def plot_record(
    result: ApproximationResult,
    path: str | os.PathLike[str],
    *,
    raw_points: NDArray[np.float64] | None = None,
    title: str = "",
) -> None:
    """``path.png``: raw points, the stored spline, its knots and the removed loops."""
    plt, fig, (ax,) = _figure()
    pts = result.points if raw_points is None else raw_points
    ax.plot(
        pts[:, 0], pts[:, 1], ".", ms=2, color="0.6", label=f"input points ({len(pts)})", zorder=1
    )
    for i, cut in enumerate(result.loops):
        ax.plot(
            cut.polyline[:, 0],
            cut.polyline[:, 1],
            "--",
            color="tab:red",
            lw=1.2,
            zorder=2,
            label=f"removed loops ({len(result.loops)})" if i == 0 else None,
        )
        ax.plot(*cut.point, "x", color="tab:red", ms=7, zorder=4)
    xy = _spline_xy(result.spline)
    if len(xy):
        ax.plot(
            xy[:, 0],
            xy[:, 1],
            "-",
            color="tab:blue",
            lw=1.5,
            zorder=3,
            label=f"stored spline ({result.spline.n_segments} segments, {result.spline.total_length:.2f} m)",
        )
        k = result.spline.knots
        ax.plot(k[:, 0], k[:, 1], "o", ms=4, mfc="white", mec="tab:blue", zorder=5, label="knots")
        ax.plot(
            *result.spline.start, "*", color="tab:green", ms=14, zorder=6, label="start (operator)"
        )
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.grid(alpha=0.3)
    ax.legend(loc="best", fontsize=8)
    ax.set_title(
        title
        or f"path memory, eps = {result.raw_spline.tolerance:g} m, "
        f"max deviation {result.max_deviation:.4g} m"
    )
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=130, bbox_inches="tight")
    plt.close(fig)


def plot_returns(
    spline: PathSpline,
    sim: ReturnSimResult,
    path: str | os.PathLike[str],
    *,
    stop_radius: float | None = None,
    title: str = "",
) -> None:
    """``returns.png``: like the paper's fig. 4 - the stored path, every run's true trajectory and
    end point, and the distribution of the final error (% of the path length)."""
    plt, fig, (ax, hx) = _figure(2, width=6.0)
    xy = _spline_xy(spline)
    for r in range(sim.true_xy.shape[1]):
        ax.plot(
            sim.true_xy[:, r, 0],
            sim.true_xy[:, r, 1],
            "-",
            color="tab:orange",
            lw=0.6,
            alpha=0.5,
            label="true return runs" if r == 0 else None,
        )
    ax.plot(
        xy[:, 0],
        xy[:, 1],
        "-",
        color="tab:blue",
        lw=2,
        label=f"stored path ({spline.total_length:.2f} m)",
    )
    ax.plot(
        sim.final_true[:, 0], sim.final_true[:, 1], ".", color="k", ms=5, label="final positions"
    )
    ax.plot(*sim.start, "*", color="tab:green", ms=14, label="start (operator)")
    if stop_radius:
        ax.add_patch(
            plt.Circle(tuple(sim.start), stop_radius, fill=False, color="tab:green", ls="--")
        )
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.grid(alpha=0.3)
    ax.legend(loc="best", fontsize=8)
    s = sim.summary()
    ax.set_title(
        title
        or f"{s['runs']} returns: final error mean {s['final_error_mean_pct']:.2f} %, "
        f"p95 {s['final_error_p95_pct']:.2f} % of L"
    )
    hx.hist(
        sim.final_error_pct, bins=max(5, len(sim.final_error) // 4), color="tab:orange", alpha=0.8
    )
    hx.axvline(s["final_error_mean_pct"], color="k", ls="-", label="mean")
    hx.axvline(s["final_error_p95_pct"], color="k", ls="--", label="95th percentile")
    hx.set_xlabel("final position error [% of path length]")
    hx.set_ylabel("runs")
    hx.legend(fontsize=8)
    hx.grid(alpha=0.3)
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=120, bbox_inches="tight")
    plt.close(fig)
