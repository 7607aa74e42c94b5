"""Paper 1's experiments in the simulator and on the recorded lidar frames, as a library.

The scene builders (:func:`paper_scenes`, :func:`scanners`), the true footprints
(:func:`footprint`, :func:`footprint_distance`, :func:`footprint_samples`), the scored experiment
(:func:`run_experiment`, :func:`noise_sweep`) and the real-data helpers (:func:`kitti_frame`,
:func:`navkit_ground`, :func:`patchwork_ground`, :func:`car_recall`) are shared by
``tests/obstacles`` and ``benchmarks/bench_obstacles.py``. Like :mod:`navkit.mission`, the
:mod:`navkit.experiments` package sits above the capabilities: it may import :mod:`navkit.sim`,
:mod:`navkit.io`, :mod:`navkit.datasets` and the capabilities, and no capability imports it.
Heavy or optional imports (the simulator, SciPy, ``pypatchworkpp``) are done inside the functions.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from navkit.errors import InputError

__all__ = [
    "KITTI_FRAMES",
    "NOISE_LEVELS",
    "SENSOR_HEIGHT_KITTI",
    "SHAPE_NAMES",
    "ExperimentResult",
    "car_recall",
    "footprint",
    "footprint_distance",
    "footprint_samples",
    "format_sweep",
    "kitti_frame",
    "navkit_ground",
    "noise_sweep",
    "paper_scenes",
    "patchwork_ground",
    "run_experiment",
    "scanners",
]

NOISE_LEVELS = (0.0, 0.005, 0.01, 0.015, 0.02, 0.025, 0.03)
SHAPE_NAMES = ("A1", "A2", "A3", "A4", "A5", "A6", "MEC", "MVEE")


# ------------------------------------------------------------------------------------------
# the paper's scenes


def paper_scenes() -> dict[str, Any]:
    """The simulated scenes of paper 1's experiments (world z up, the robot at the origin).

    ``box``: a 1 m cube 6 m ahead; ``hemisphere``: a dome of radius 0.8 m 6 m ahead; ``four``: the
    map with four obstacles - two boxes (1, 3), a prism whose slanted side is parallel to y and
    rises at 45 deg (> c0 = 20 deg) away from the robot (2), a hemisphere (4); ``ramp``: a
    gentle 9.5 deg ramp (traversable: not an obstacle).
    """
    from navkit.sim import Box, Ground, Hemisphere, Prism, Scene

    return {
        "box": Scene([Ground(), Box(center=(6.0, 0.0, 0.5), size=(1.0, 1.0, 1.0), name="box")]),
        "hemisphere": Scene(
            [Ground(), Hemisphere(center=(6.0, 0.0, 0.0), radius=0.8, name="dome")]
        ),
        "four": Scene(
            [
                Ground(),
                Box(center=(6.0, 2.5, 0.5), size=(1.0, 1.0, 1.0), name="box1"),
                Prism(center=(8.0, -1.0, 0.5), size=(1.0, 2.0, 1.0), name="prism2"),
                Box(
                    center=(5.0, -4.0, 0.6), size=(0.8, 1.2, 1.2), yaw=math.radians(30), name="box3"
                ),
                Hemisphere(center=(11.0, 1.5, 0.0), radius=1.0, name="dome4"),
            ]
        ),
        "ramp": Scene(
            [Ground(), Prism(center=(7.0, 0.0, 0.25), size=(3.0, 2.0, 0.5), name="ramp")]
        ),
    }


def scanners() -> dict[str, tuple[Any, float]]:
    """``name -> (scanner, sensor height m)``: the SICK-like tilting scanner and a 64-beam lidar."""
    from navkit.sim import SpinningLidar, TiltingScanner

    return {
        "tilting": (
            TiltingScanner(
                azimuth_min_deg=-90,
                azimuth_max_deg=90,
                azimuth_step_deg=1,
                elevation_min_deg=-40,
                elevation_max_deg=0,
                elevation_step_deg=1,
            ),
            2.0,
        ),
        "spinning64": (
            SpinningLidar(
                n_beams=64, n_columns=2048, elevation_min_deg=-24.8, elevation_max_deg=2.0
            ),
            1.73,
        ),
    }


def footprint(prim: Any) -> tuple[str, NDArray[np.float64]]:
    """True footprint of a primitive on the ground: ``("polygon", (4, 2))`` or ``("circle", (3,))``
    (from :func:`navkit.sim.footprints.footprint`, the one home of primitive footprints)."""
    from navkit.sim.footprints import footprint as sim_footprint

    kind = type(prim).__name__
    fp = (
        sim_footprint(prim)
        if kind in ("Box", "Prism", "Hemisphere", "Sphere", "Cylinder")
        else None
    )
    if fp is None:
        raise InputError(
            f"has no footprint (type {kind})",
            field="prim",
            expected="a Box, Prism, Hemisphere, Sphere or Cylinder",
        )
    return ("circle", fp.circle) if fp.circle is not None else ("polygon", fp.polygon)


def footprint_distance(
    fp: tuple[str, NDArray[np.float64]], xy: NDArray[np.float64]
) -> NDArray[np.float64]:
    """Distance (m) of points ``(N, 2)`` to the outline of a footprint."""
    kind, g = fp
    if kind == "circle":
        return np.abs(np.hypot(xy[:, 0] - g[0], xy[:, 1] - g[1]) - g[2])
    a, b = g, np.roll(g, -1, axis=0)
    ab = b - a
    t = np.clip(
        np.einsum("nki,ki->nk", xy[:, None, :] - a[None], ab) / np.einsum("ki,ki->k", ab, ab), 0, 1
    )
    closest = a[None] + t[..., None] * ab[None]
    return np.linalg.norm(xy[:, None, :] - closest, axis=-1).min(axis=1)


def footprint_samples(
    fp: tuple[str, NDArray[np.float64]], n: int = 40
) -> tuple[NDArray[np.float64], float]:
    """A grid of points filling the footprint ``(M, 2)`` and its area (m^2)."""
    kind, g = fp
    if kind == "circle":
        u = np.linspace(-1, 1, n)
        U, V = np.meshgrid(u, u)
        m = U**2 + V**2 <= 1
        return np.column_stack([g[0] + g[2] * U[m], g[1] + g[2] * V[m]]), math.pi * g[2] ** 2
    s, t = np.meshgrid(np.linspace(0, 1, n), np.linspace(0, 1, n))
    p0, p1, p3 = g[0], g[1], g[3]
    pts = p0 + s.ravel()[:, None] * (p1 - p0) + t.ravel()[:, None] * (p3 - p0)
    e1, e2 = p1 - p0, p3 - p0
    area = abs(e1[0] * e2[1] - e1[1] * e2[0])
    return pts, float(area)


@dataclass(frozen=True)
class ExperimentResult:
    """Scores of one detection in one simulated scene against the truth."""

    scene: str
    scanner: str
    noise: float
    seed: int
    n_true: int
    n_found: int
    n_phantoms: int
    found: dict[str, int]  # true obstacle name -> detected obstacle id (0 = missed)
    boundary_error_m: float  # mean distance of the matched boundary vertices to the true outline
    containment: dict[str, float]  # shape -> mean fraction of the true footprint inside
    area_ratio: dict[str, float]  # shape -> mean area / true footprint area
    slope_as_ground: float  # ramp scene: share of the slope face's points labelled ground
    detection: Any
    sim: Any


def run_experiment(
    scene_name: str, scanner_name: str, noise: float, seed: int = 0, settings: Any = None
) -> ExperimentResult:
    """Render one scan of a paper scene, detect obstacles, score against the truth.

    A detected obstacle is matched to the true primitive hit by most of its vertices; it is a
    *phantom* when most of its vertices are ground hits. Containment: share of a grid filling the
    true footprint that lies inside the shape of the matched obstacle (A7 = ``A7:A1``, the A1
    rectangle over obstacle + shadows).
    """
    from navkit.geometry import se3_from_rt
    from navkit.obstacles import ObstacleSettings, detect_obstacles
    from navkit.obstacles.detector import unsort_vertex_array
    from navkit.sim import render_scan
    from navkit.sim.scanners import RangeNoise

    scene = paper_scenes()[scene_name]
    scanner, height = scanners()[scanner_name]
    settings = settings or ObstacleSettings()
    T = se3_from_rt(np.eye(3), [0.0, 0.0, height])
    sim = render_scan(
        scene, scanner, T, noise=RangeNoise(relative_sigma=noise), rng=seed, max_range=60.0
    )
    det = detect_obstacles(sim.scan, settings)
    vid = unsort_vertex_array(sim.scan, det.vertex_obstacle)
    hit = sim.hit_index
    ground_idx = {i for i, p in enumerate(scene.primitives) if getattr(p, "is_ground", False)}
    true_idx = [i for i, p in enumerate(scene.primitives) if i not in ground_idx]
    if scene_name == "ramp":  # the gentle ramp is traversable: scored by its slope face only
        true_idx = []
    found = {scene.primitives[i].name: 0 for i in true_idx}
    phantoms = 0
    match: dict[int, int] = {}
    for ob in det.obstacles:
        h = hit[vid == ob.id]
        h = h[h >= 0]
        if h.size == 0:
            phantoms += 1
            continue
        vals, counts = np.unique(h, return_counts=True)
        top = int(vals[np.argmax(counts)])
        if top in ground_idx:
            phantoms += 1
        elif scene_name == "ramp":
            continue  # the ramp's vertical side faces are real (small) obstacles
        else:
            match.setdefault(top, ob.id)
            if found[scene.primitives[top].name] == 0:
                found[scene.primitives[top].name] = ob.id
    errs: list[NDArray[np.float64]] = []
    cont: dict[str, list[float]] = {}
    area: dict[str, list[float]] = {}
    byid = {o.id: o for o in det.obstacles}
    for prim_i, ob_id in match.items():
        ob = byid[ob_id]
        fp = footprint(scene.primitives[prim_i])
        errs.append(footprint_distance(fp, ob.boundary_xy))
        samples, fp_area = footprint_samples(fp)
        for name, shp in [*ob.shapes.items(), *((f"A7:{k}", v) for k, v in ob.guaranteed.items())]:
            cont.setdefault(name, []).append(float(shp.contains(samples, 1e-9).mean()))
            area.setdefault(name, []).append(shp.area / fp_area)
    slope_ground = float("nan")
    if scene_name == "ramp":
        # rays that hit the ramp's slope face (true normal tilted by its slope, < c0)
        nrm = sim.normals_world
        on_slope = (hit == 1) & (np.abs(nrm[..., 2]) > math.cos(math.radians(15))) & sim.scan.valid
        vlab = unsort_vertex_array(sim.scan, det.vertex_labels)
        slope_ground = float(np.mean(vlab[on_slope] == 0)) if on_slope.any() else float("nan")
    return ExperimentResult(
        scene=scene_name,
        slope_as_ground=slope_ground,
        scanner=scanner_name,
        noise=noise,
        seed=seed,
        n_true=len(true_idx),
        n_found=sum(v > 0 for v in found.values()),
        n_phantoms=phantoms,
        found=found,
        boundary_error_m=float(np.mean(np.concatenate(errs))) if errs else float("nan"),
        containment={k: float(np.mean(v)) for k, v in cont.items()},
        area_ratio={k: float(np.mean(v)) for k, v in area.items()},
        detection=det,
        sim=sim,
    )


def noise_sweep(
    seeds: tuple[int, ...] = (0, 1, 2),
    scanners_: tuple[str, ...] = ("tilting", "spinning64"),
    scenes: tuple[str, ...] = ("box", "hemisphere", "four", "ramp"),
    levels: tuple[float, ...] = NOISE_LEVELS,
) -> list[dict[str, Any]]:
    """The noise-sweep table: one row per (scanner, noise level), summed over scenes and seeds."""
    rows = []
    for sc in scanners_:
        for noise in levels:
            n_true = n_found = n_ph = 0
            berr: list[float] = []
            cont: dict[str, list[float]] = {}
            area: dict[str, list[float]] = {}
            for scene in scenes:
                for seed in seeds:
                    r = run_experiment(scene, sc, noise, seed)
                    n_true += r.n_true
                    n_found += r.n_found
                    n_ph += r.n_phantoms
                    if np.isfinite(r.boundary_error_m):
                        berr.append(r.boundary_error_m)
                    for k, v in r.containment.items():
                        cont.setdefault(k, []).append(v)
                    for k, v in r.area_ratio.items():
                        area.setdefault(k, []).append(v)
            rows.append(
                {
                    "scanner": sc,
                    "noise": noise,
                    "found": n_found,
                    "true": n_true,
                    "phantoms": n_ph,
                    "boundary_error_m": float(np.mean(berr)) if berr else float("nan"),
                    "containment": {k: float(np.mean(v)) for k, v in cont.items()},
                    "area_ratio": {k: float(np.mean(v)) for k, v in area.items()},
                }
            )
    return rows


def format_sweep(rows: list[dict[str, Any]]) -> str:
    """The sweep as a Markdown table."""
    head = (
        "| scanner | noise % | found / true | phantoms | boundary err (m) | "
        + " | ".join(f"{s} cont. / area" for s in ("A1", "A3", "A6", "MEC", "MVEE", "A7:A1"))
        + " |"
    )
    lines = [head, "|" + "---|" * (5 + 6)]
    for r in rows:
        cells = []
        for s in ("A1", "A3", "A6", "MEC", "MVEE", "A7:A1"):
            c, a = r["containment"].get(s, float("nan")), r["area_ratio"].get(s, float("nan"))
            cells.append(f"{c:.2f} / {a:.2f}")
        lines.append(
            f"| {r['scanner']} | {100 * r['noise']:.1f} | {r['found']} / {r['true']} | {r['phantoms']} | "
            f"{r['boundary_error_m']:.3f} | " + " | ".join(cells) + " |"
        )
    return "\n".join(lines)


# ------------------------------------------------------------------------------------------
# real data


KITTI_FRAMES = ("000000", "000001", "000002")
SENSOR_HEIGHT_KITTI = 1.73


def kitti_frame(name: str) -> tuple[NDArray[np.float32], NDArray[np.uint16]]:
    """Points ``(N, 4)`` and semantic classes ``(N,)`` of a SemanticKITTI frame."""
    from navkit import datasets
    from navkit.io.pointcloud import read_kitti_bin, read_kitti_labels

    folder = datasets.find("lidar/semantickitti-seq00")
    pts = read_kitti_bin(folder / f"{name}.bin")
    sem, _ = read_kitti_labels(folder / f"{name}.label", n_points=len(pts))
    return pts, sem


def navkit_ground(
    points: NDArray[np.float32], settings: Any = None
) -> tuple[NDArray[np.bool_], Any, Any]:
    """navkit's per-point ground mask, detection and grid for a KITTI cloud."""
    from navkit.obstacles import Mounting, detect_obstacles_in_grid
    from navkit.obstacles.grids import cloud_to_grid
    from navkit.obstacles.rules import GROUND

    grid = cloud_to_grid(points)
    det = detect_obstacles_in_grid(grid, Mounting(SENSOR_HEIGHT_KITTI), settings)
    return grid.per_point(det.vertex_labels) == GROUND, det, grid


def patchwork_ground(pw: Any, points: NDArray[np.float32]) -> NDArray[np.bool_]:
    """Patchwork++'s per-point ground mask."""
    pw.estimateGround(points)
    mask = np.zeros(len(points), dtype=bool)
    mask[np.asarray(pw.getGroundIndices(), dtype=np.int64)] = True
    return mask


def car_recall(
    settings: Any = None, min_points: int = 50, min_inside: float = 0.95
) -> tuple[int, int, list[dict[str, Any]]]:
    """Cars of the SqueezeSeg frames (8-connected components of the car mask with >= min_points
    returns) found: the obstacle that owns most of the car's points has an A1 rectangle holding
    >= ``min_inside`` of them. Returns (found, total, per-car details, with the rectangle's area
    over the car's own bounding box to show the obstacle is car-sized)."""
    from scipy import ndimage

    from navkit import datasets
    from navkit.obstacles import Mounting, detect_obstacles_in_grid
    from navkit.obstacles.evaluate import shape_contains
    from navkit.obstacles.grids import organized_to_grid

    folder = datasets.find("lidar/squeezeseg-kitti-raw")
    found = total = 0
    details = []
    for f in sorted(folder.glob("*.npy")):
        x = np.load(f)
        P = x[..., :3].astype(np.float64)
        P[x[..., 4] == 0] = np.nan
        grid = organized_to_grid(P, source=f.name)
        det = detect_obstacles_in_grid(grid, Mounting(SENSOR_HEIGHT_KITTI), settings, source=f.name)
        cars, n = ndimage.label(x[..., 5] == 1, structure=np.ones((3, 3)))
        for k in range(1, n + 1):
            m = (cars == k) & (x[..., 4] > 0)
            if m.sum() < min_points:
                continue
            total += 1
            xy = x[..., :2][m].astype(np.float64)
            # the obstacle owning most of the car's points (stage 7 gives each point its obstacle)
            owner_ids = grid.per_point(det.vertex_obstacle).reshape(m.shape)[m]
            owner_ids = owner_ids[owner_ids > 0]
            ob = None
            if owner_ids.size:
                ob = det.obstacles[int(np.bincount(owner_ids).argmax()) - 1]
            fr = float(ob.shapes["A1"].contains(xy).mean()) if ob is not None else 0.0
            ok = fr >= min_inside
            found += ok
            lo, hi = xy.min(axis=0), xy.max(axis=0)
            details.append(
                {
                    "frame": f.stem,
                    "points": int(m.sum()),
                    "range_m": float(np.hypot(*xy.mean(axis=0))),
                    "inside": fr,
                    "found": bool(ok),
                    "inside_any_obstacle": float(shape_contains(det.obstacles, xy, ["A1"]).mean()),
                    "rect_area_over_car_box": (ob.shapes["A1"].area / max(np.prod(hi - lo), 1e-6))
                    if ob
                    else float("nan"),
                }
            )
    return found, total, details
