"""``navkit map``: build a 2D wall map, and localize scans / stereo frames in it.

- ``navkit map build INPUT --out DIR [--every N]``: INPUT is a CARMEN log (``.log`` /
  ``.log.gz``; the scans with their corrected poses) or a stereo frame folder (``calib.yaml``,
  ``poses.tum``, ``left/``, ``right/``; see ``navkit stereo simulate``). Writes ``map.json``
  (walls with extents and uncertainty, corners, outline), ``map.pgm`` + ``map.yaml`` (ROS
  map_server occupancy grid), ``map.png``, ``summary.json`` (with the map's accuracy when the
  folder holds a ``truth.json``) and ``settings.toml``.
- ``navkit map locate MAP_JSON INPUT --out DIR [--prior none|odometry]``: localizes every
  (N-th) scan / frame of INPUT without its pose (``none``: global search over the whole map and
  all headings) or from a coarse prior (``odometry``: the previous fix moved by the odometry
  increment; the first fix is global). Writes ``poses.tum`` (x, y, yaw per scan at the scan's
  own timestamp, z = 0), ``fixes.csv`` (score and ambiguity of each fix), ``locate.png``,
  ``summary.json`` (ms per fix; errors against the log's corrected poses or the frames' poses)
  and ``settings.toml``.
"""

from __future__ import annotations

import dataclasses
import logging
import time
from dataclasses import dataclass
from enum import Enum
from pathlib import Path
from typing import Any

import typer

from navkit.cli.common import cli_errors, progress, write_run_files

log = logging.getLogger(__name__)

map_app = typer.Typer(
    help="2D wall maps and localization by correlation (paper 3).", no_args_is_help=True
)


class PriorChoice(str, Enum):
    none = "none"
    odometry = "odometry"


@dataclass(frozen=True)
class BuildInput:
    input: str
    kind: str
    every: int
    max_range: float


@dataclass(frozen=True)
class LocateInput:
    map: str
    input: str
    kind: str
    every: int
    group: int
    prior: str
    max_range: float
    sigma: float
    success_m: float
    success_deg: float
    known_heading: bool
    refine: bool


@dataclass(frozen=True)
class _FixRecord:
    """One row of ``fixes.csv``: a correlative or a known-heading fix, after refinement."""

    pose: Any  # (3,) x, y, theta
    score: float
    ok: bool
    ambiguous: bool
    reason: str
    direction: Any  # (2,) along the peak / the wall
    extent: float
    second_score: float
    exact: bool
    seconds: float
    refinement: Any  # PoseRefinement or None

    @property
    def refined(self) -> bool:
        rf = self.refinement
        return bool(rf is not None and rf.converged and not rf.degenerate)


def _is_carmen(path: Path) -> bool:
    return path.is_file()


def _heading_of_camera(T: Any) -> Any:
    """Heading (rad) of the optical axis of ``T_world_camera`` ``(..., 4, 4)`` in the world plane."""
    import numpy as np

    z = T[..., :3, 2]
    return np.arctan2(z[..., 1], z[..., 0])


@map_app.command("build")
def build_cmd(
    input: Path = typer.Argument(..., help="CARMEN log (.log/.log.gz) or stereo frame folder."),
    out: Path = typer.Option(..., "--out", help="Output folder."),
    every: int = typer.Option(1, "--every", min=1, help="Use every N-th scan / frame."),
    resolution: float = typer.Option(0.05, help="Occupancy grid cell, metres."),
    max_range: float = typer.Option(
        30.0, help="Laser readings at or beyond this (metres) are no return."
    ),
) -> None:
    """Build a wall map (JSON, occupancy grid PGM + YAML, PNG) from scans or stereo frames with poses."""
    with cli_errors():
        import json
        import time

        import numpy as np

        from navkit.io.atomic import write_json
        from navkit.io.maps import write_occupancy_grid
        from navkit.localization import MapSettings, build_map, build_map_from_scans, evaluate_map
        from navkit.viz.maps import plot_map

        settings = MapSettings(resolution=resolution)
        t0 = time.perf_counter()
        truth = None
        if not input.exists():
            from navkit.errors import DataNotFoundError

            raise DataNotFoundError(f"{input}: no such CARMEN log or stereo frame folder")
        if _is_carmen(input):
            from navkit.io.carmen import read_carmen

            lg = read_carmen(input)
            sel = np.arange(0, len(lg), every)
            wall_map = build_map_from_scans(
                lg.ranges[sel], lg.bearings, lg.poses[sel], settings, max_range=max_range
            )
            kind, n = "carmen", len(sel)
        else:
            from navkit.io.images import read_image
            from navkit.io.stereo import read_stereo_frames
            from navkit.stereo import stereo_wall_points

            fr = read_stereo_frames(input)
            sel = np.arange(0, len(fr), every)
            views = []
            for k in progress(sel, "stereo frames"):
                views.append(
                    stereo_wall_points(
                        read_image(fr.left[k]),
                        read_image(fr.right[k]),
                        fr.rig,
                        T_world_camera=fr.poses[k],
                    )
                )
            wall_map = build_map(views, None, settings)
            kind, n = "stereo", len(sel)
            if (input / "truth.json").is_file():
                truth = json.loads((input / "truth.json").read_text())
        seconds = time.perf_counter() - t0
        out.mkdir(parents=True, exist_ok=True)
        assert wall_map.occupancy is not None  # the builders always rasterise
        write_occupancy_grid(out / "map", wall_map.occupancy, wall_map.resolution, wall_map.origin)
        write_json(
            out / "map.json", {**wall_map.to_dict(), "grid": "map.yaml", "source": str(input)}
        )
        plot_map(
            wall_map,
            out / "map.png",
            true_walls=None if truth is None else truth["walls"],
            title=f"{input.name}: {len(wall_map.walls)} walls, {len(wall_map.corners)} corners",
        )
        summary: dict[str, Any] = {
            "input_kind": kind,
            "views": n,
            "walls": len(wall_map.walls),
            "corners": len(wall_map.corners),
            "outline_vertices": 0 if wall_map.outline is None else len(wall_map.outline),
            "seconds": seconds,
        }
        if truth is not None:
            summary["accuracy"] = evaluate_map(wall_map, truth["walls"], truth["corners"])
            summary["room_size_m"] = truth["size"]
        write_run_files(
            out, {"input": BuildInput(str(input), kind, every, max_range), "map": settings}, summary
        )
        typer.echo(
            f"map: {len(wall_map.walls)} walls, {len(wall_map.corners)} corners from {n} {kind} views -> {out}"
        )


def load_map(path: Path):  # type: ignore[no-untyped-def]
    """A :class:`WallMap` from ``map.json`` (with its occupancy grid when the file names one)."""
    import dataclasses
    import json

    from navkit.errors import DataNotFoundError, FormatError
    from navkit.localization import WallMap

    if not path.is_file():
        raise DataNotFoundError(f"{path}: no such map file")
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise FormatError(
            f"not JSON: {exc}", source=path, expected="a map.json written by navkit map build"
        ) from None
    wall_map = WallMap.from_dict(data, source=str(path))
    grid = data.get("grid")
    if grid and (path.parent / grid).is_file():
        from navkit.io.maps import read_occupancy_grid

        g = read_occupancy_grid(path.parent / grid)
        wall_map = dataclasses.replace(
            wall_map, occupancy=g.occupancy, resolution=g.resolution, origin=g.origin_xy
        )
    return wall_map


@map_app.command("locate")
def locate_cmd(
    map_json: Path = typer.Argument(..., help="map.json from navkit map build."),
    input: Path = typer.Argument(..., help="CARMEN log or stereo frame folder to localize."),
    out: Path = typer.Option(..., "--out", help="Output folder."),
    prior: PriorChoice = typer.Option(
        PriorChoice.none, help="none: global search; odometry: last fix + odometry."
    ),
    every: int = typer.Option(
        1, "--every", min=1, help="Localize every N-th scan / frame (group)."
    ),
    group: int = typer.Option(
        1,
        "--group",
        min=1,
        help="Stereo: N consecutive frames taken at one place form one fragment.",
    ),
    max_range: float = typer.Option(
        30.0, help="Laser readings at or beyond this (metres) are no return."
    ),
    sigma: float = typer.Option(0.1, help="Likelihood field width, metres."),
    success_m: float = typer.Option(
        0.3, help="A fix within this (metres) of the reference is a success."
    ),
    success_deg: float = typer.Option(5.0, help="... and within this heading error, degrees."),
    known_heading: bool = typer.Option(
        False,
        "--known-heading",
        help="Paper 3's method: the heading is known (the camera drive's angle sensor; here the "
        "reference pose's heading) and the fragment is slid over the map by correlation. "
        "Ambiguous views (one straight wall, twin corners, a wall the map predicts but the "
        "camera did not see) are reported, not fixed.",
    ),
    refine: bool | None = typer.Option(
        None,
        "--refine/--no-refine",
        help="Refine each fix by weighted point-to-line least squares against the map's walls "
        "(kept only when it converges and is not degenerate along a wall). Default: on for "
        "stereo frames, off for laser logs (a real building is not all straight walls: on the "
        "Intel log it raises the median error from 1.1 to 2.8 cm).",
    ),
) -> None:
    """Localize scans / frames in a wall map by correlative matching; poses as TUM, fixes as CSV."""
    with cli_errors():
        import numpy as np

        from navkit.geometry import (
            se2_apply,
            se2_compose,
            se2_from_xytheta,
            se2_inverse,
            se2_to_xytheta,
            se3_from_rt,
            wrap_angle,
        )
        from navkit.io.atomic import atomic_write
        from navkit.io.trajectory import Trajectory, write_tum
        from navkit.localization import MatcherSettings, match_scan, refine_pose
        from navkit.localization.correlation import locate_known_heading
        from navkit.localization.refine import stereo_range_sigma
        from navkit.viz.maps import plot_map

        wall_map = load_map(map_json)
        fld = wall_map.likelihood_field(sigma)
        settings = MatcherSettings()
        if not input.exists():
            from navkit.errors import DataNotFoundError

            raise DataNotFoundError(f"{input}: no such CARMEN log or stereo frame folder")
        if _is_carmen(input):
            from navkit.io.carmen import read_carmen

            lg = read_carmen(input)
            sel = np.arange(0, len(lg), every)
            kind = "carmen"
            stamps = lg.timestamps[sel]
            reference = lg.poses[sel]
            odom = lg.odom_poses[sel]

            def points(k: int) -> Any:
                return lg.points(int(sel[k]), max_range)

            def range_sigma(pts: Any) -> Any:
                return None  # laser: every point weighs the same

            view = None
        else:
            from navkit.io.images import read_image
            from navkit.io.stereo import read_stereo_frames
            from navkit.stereo import stereo_wall_points

            fr = read_stereo_frames(input)
            if len(fr) % group:
                from navkit.errors import InputError

                raise InputError(
                    f"{len(fr)} frames are not a multiple of --group {group}",
                    source=input,
                    field="--group",
                    expected="groups of frames taken at one place",
                )
            sel = np.arange(0, len(fr), group)[::every]
            kind = "stereo"
            stamps = fr.timestamps[sel]
            T = fr.poses[sel]
            reference = np.column_stack([T[:, 0, 3], T[:, 1, 3], _heading_of_camera(T)])
            odom = reference  # the frames' poses serve as odometry for the tracking prior
            planar = np.column_stack(
                [fr.poses[:, 0, 3], fr.poses[:, 1, 3], _heading_of_camera(fr.poses)]
            )

            def points(k: int) -> Any:
                # the group's frames, each moved into the first frame's body frame by its relative
                # planar pose (relative headings from the camera drive, paper 3)
                j0 = int(sel[k])
                first = se2_from_xytheta(*planar[j0])
                parts = []
                for j in range(j0, j0 + group):
                    B = stereo_wall_points(
                        read_image(fr.left[j]),
                        read_image(fr.right[j]),
                        fr.rig,
                        camera_height=float(fr.poses[j][2, 3]),
                    )
                    rel = se2_compose(se2_inverse(first), se2_from_xytheta(*planar[j]))
                    parts.append(se2_apply(rel, B) if len(B) else B)
                return np.concatenate(parts)

            def range_sigma(pts: Any) -> Any:
                return stereo_range_sigma(pts, fr.rig.baseline, fr.rig.camera.fx)

            if group == 1:  # the view of one frame, for the negative-information check
                from navkit.localization.visibility import ViewModel
                from navkit.stereo.floorplan import (
                    FloorplanSettings,
                    default_num_disparities,
                    usable_depth,
                )

                fp = FloorplanSettings()
                view = ViewModel.from_stereo(
                    fr.rig,
                    max_depth=usable_depth(fr.rig, fp),
                    num_disparities=default_num_disparities(fr.rig, fp),
                    disparity_sigma=fp.disparity_sigma,
                )

        if refine is None:
            refine = kind == "stereo"
        est = np.full((len(sel), 3), np.nan)
        records: list[_FixRecord | None] = []  # one per fix (None: no points)
        last = None
        for k in progress(range(len(sel)), "localizing"):
            pts = points(k)
            if len(pts) < 3:
                records.append(None)
                continue
            if known_heading:
                t0 = time.perf_counter()  # wall time, as match_scan's own timer
                kf = locate_known_heading(
                    fld,
                    pts,
                    float(reference[k, 2]),
                    walls=wall_map.walls if refine and wall_map.walls else None,
                    range_sigma=range_sigma(pts),
                    region=wall_map.outline if len(wall_map.outline) >= 3 else None,
                    view=view if refine else None,
                )
                rec = _FixRecord(
                    np.array([*kf.position, reference[k, 2]]),
                    kf.score,
                    kf.ok,
                    kf.ambiguous,
                    kf.reason,
                    kf.peak_direction,
                    kf.peak_extent,
                    kf.second_score,
                    True,  # the FFT correlation scores every offset
                    time.perf_counter() - t0,
                    kf.refinement,
                )
            else:
                guess = None
                if prior == PriorChoice.odometry and last is not None:
                    delta = se2_compose(
                        se2_inverse(se2_from_xytheta(*odom[last[0]])), se2_from_xytheta(*odom[k])
                    )
                    guess = se2_to_xytheta(se2_compose(se2_from_xytheta(*last[1]), delta))
                fix = match_scan(fld, pts, guess, settings)
                a = fix.ambiguity
                rf = None
                if refine and wall_map.walls:
                    rf = refine_pose(wall_map.walls, pts, fix.pose, range_sigma=range_sigma(pts))
                rec = _FixRecord(
                    fix.pose,
                    fix.score,
                    fix.ok,
                    a.ambiguous,
                    a.reason,
                    a.direction,
                    a.extent,
                    a.second_score,
                    fix.exact,
                    fix.seconds,
                    rf,
                )
                if rf is not None and rec.refined:
                    rec = dataclasses.replace(rec, pose=rf.pose)
            est[k] = rec.pose
            last = (k, rec.pose)
            records.append(rec)
        # outputs
        out.mkdir(parents=True, exist_ok=True)
        found = np.all(np.isfinite(est), axis=1)
        yaw = np.where(found, est[:, 2], 0.0)
        Rz = np.zeros((len(sel), 3, 3))
        Rz[:, 0, 0], Rz[:, 0, 1], Rz[:, 1, 0], Rz[:, 1, 1], Rz[:, 2, 2] = (
            np.cos(yaw),
            -np.sin(yaw),
            np.sin(yaw),
            np.cos(yaw),
            1,
        )
        poses = se3_from_rt(Rz, np.column_stack([est[:, 0], est[:, 1], np.zeros(len(sel))]))
        write_tum(out / "poses.tum", Trajectory(stamps[found], poses[found]))
        pos_err = np.hypot(est[:, 0] - reference[:, 0], est[:, 1] - reference[:, 1])
        head_err = np.degrees(np.abs(wrap_angle(est[:, 2] - reference[:, 2])))
        with atomic_write(out / "fixes.csv") as fh:
            fh.write(
                "index,timestamp,x,y,theta,score,ok,ambiguous,reason,direction_x,direction_y,extent_m,"
                "second_score,exact,ms,refined,refine_rms_m,refine_sigma_weak_m,"
                "ref_x,ref_y,ref_theta,position_error_m,heading_error_deg\n"
            )
            for k, row in enumerate(records):
                r = reference[k]
                if row is None:
                    fh.write(
                        f"{sel[k]},{stamps[k]:.6f},,,,,False,,no points,,,,,,,,,,"
                        f"{r[0]:.4f},{r[1]:.4f},{r[2]:.5f},,\n"
                    )
                    continue
                rf = row.refinement
                rcols = (
                    f"{row.refined},{rf.rms:.4f},{rf.sigma_weak:.4f}"
                    if rf is not None
                    else "False,,"
                )
                e, d = row.pose, row.direction
                fh.write(
                    f"{sel[k]},{stamps[k]:.6f},{e[0]:.4f},{e[1]:.4f},{e[2]:.5f},{row.score:.4f},"
                    f"{row.ok},{row.ambiguous},{row.reason},{d[0]:.4f},{d[1]:.4f},{row.extent:.3f},"
                    f"{row.second_score:.4f},{row.exact},{1e3 * row.seconds:.2f},{rcols},"
                    f"{r[0]:.4f},{r[1]:.4f},{r[2]:.5f},"
                    f"{pos_err[k]:.4f},{head_err[k]:.3f}\n"
                )
        fixes = [f for f in records if f is not None]
        ms = np.array([1e3 * f.seconds for f in fixes]) if fixes else np.array([np.nan])
        ok = np.array([f is not None and f.ok for f in records])
        success = found & (pos_err <= success_m) & (head_err <= success_deg)
        pe = pos_err[found]
        summary: dict[str, Any] = {
            "input_kind": kind,
            "fixes": len(sel),
            "prior": prior.value,
            "ms_per_fix_median": float(np.median(ms)),
            "ms_per_fix_mean": float(np.mean(ms)),
            "ms_per_fix_p95": float(np.percentile(ms, 95)),
            "method": "known heading (paper 3)" if known_heading else "correlative matching",
            "refined_rate": float(np.mean([f is not None and f.refined for f in records])),
            "ok_rate": float(ok.mean()),
            "success_rate": float(success.mean()),
            "success_rate_of_ok": float(success[ok].mean()) if ok.any() else float("nan"),
            "false_fix_rate": float((ok & ~success).mean()),
            "ambiguous_rate": float(np.mean([f.ambiguous for f in fixes]))
            if fixes
            else float("nan"),
            "position_error_m_median": float(np.median(pe)) if len(pe) else float("nan"),
            "position_error_m_p95": float(np.percentile(pe, 95)) if len(pe) else float("nan"),
            "heading_error_deg_median": float(np.median(head_err[found]))
            if found.any()
            else float("nan"),
            "reference": "corrected poses of the log"
            if kind == "carmen"
            else "poses.tum of the frames",
        }
        if wall_map.walls:
            lo, hi = wall_map.bounds
            size = float(np.linalg.norm(hi - lo))
            summary["map_diagonal_m"] = size
            summary["position_error_relative_median"] = summary["position_error_m_median"] / size
        plot_map(
            wall_map,
            out / "locate.png",
            poses=est,
            truth=reference,
            title=f"{input.name}: {100 * summary['success_rate']:.0f}% within {success_m} m",
        )
        write_run_files(
            out,
            {
                "input": LocateInput(
                    str(map_json),
                    str(input),
                    kind,
                    every,
                    group,
                    prior.value,
                    max_range,
                    sigma,
                    success_m,
                    success_deg,
                    known_heading,
                    refine,
                ),
                "matcher": settings,
            },
            summary,
        )
        typer.echo(
            f"{len(sel)} fixes: {100 * summary['success_rate']:.1f}% within {success_m} m / {success_deg} deg, "
            f"median error {summary['position_error_m_median']:.3f} m, {summary['ms_per_fix_median']:.1f} ms per fix -> {out}"
        )


def register(app: typer.Typer) -> None:
    app.add_typer(map_app, name="map")
