"""The mission's outputs: report and metrics agree, standard formats read back, the CLI, a browser."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest

from navkit.mission import mission_metrics
from navkit.mission.demo import write_outputs
from navkit.sim.scene_io import scene_to_toml
from navkit.viz.mission import write_report

from .conftest import small_scene


@pytest.fixture(scope="module")
def outputs(mission_run, tmp_path_factory):
    out = tmp_path_factory.mktemp("mission_out")
    metrics = mission_metrics(mission_run)
    files = write_outputs(mission_run, metrics, out, report=write_report)
    return out, files, metrics


def _report_rows(html: str) -> dict[str, str]:
    rows = re.findall(
        r"<tr><td>([^<]*)</td><td>[^<]*</td><td(?: class=\"num\")?>([^<]*)</td></tr>", html
    )
    return {k.replace("&amp;", "&"): v for k, v in rows}


def test_report_and_metrics_exist_and_agree(outputs):
    out, files, _ = outputs
    for f in (
        "report.html",
        "metrics.json",
        "truth.tum",
        "vo.tum",
        "estimate.tum",
        "path.json",
        "obstacle_map.pgm",
        "obstacle_map.yaml",
    ):
        assert (out / f).is_file() and f in files
    saved = json.loads((out / "metrics.json").read_text())
    rows = _report_rows((out / "report.html").read_text())
    ret, pe, ob = saved["return"], saved["pose_error"], saved["obstacles"]
    assert float(rows["final distance to the operator (truth)"]) == pytest.approx(
        ret["final_distance_to_operator_m"], rel=1e-3
    )
    mean_vo, max_vo = (float(v) for v in rows["position error, raw VO: mean / max"].split("/"))
    assert mean_vo == pytest.approx(pe["raw_vo_m"]["mean"], abs=5e-4)
    assert max_vo == pytest.approx(pe["raw_vo_m"]["max"], abs=5e-4)
    mean_c, _ = (float(v) for v in rows["position error, corrected: mean / max"].split("/"))
    assert mean_c == pytest.approx(pe["corrected_m"]["mean"], abs=5e-4)
    assert int(rows["phantom obstacles"]) == ob["phantoms"]
    rec, rec_large = (
        float(v) for v in rows["obstacle recall (all seen / larger than the robot)"].split("/")
    )
    assert rec == pytest.approx(ob["recall"], abs=5e-4) and rec_large == pytest.approx(
        ob["recall_larger_than_robot"], abs=5e-4
    )
    # the plane and room maps say what they compare, with the run's own figures
    html_text = (out / "report.html").read_text()
    room = saved["room"]
    assert "compared with the true walls" in html_text
    assert f"{room['fixes_used']} of {room['fixes_attempted']} fixes used" in html_text
    if "corner_error_mean_m" in room:
        assert f"corner error mean {100 * room['corner_error_mean_m']:.1f} cm" in html_text
    planes = saved["planes"]
    assert f"{planes['ok']} of {planes['pairs']} frame pairs gave a plane motion" in html_text
    # every capability's time per step is reported
    for key in ("obstacles_detect", "planes_motion", "localize", "path_record", "return_control"):
        assert saved["timing"][key]["calls"] > 0 and saved["timing"][key]["mean_ms"] > 0


def test_trajectories_and_maps_read_back(outputs, mission_run):
    from navkit.io.maps import read_occupancy_grid
    from navkit.io.pathjson import read_path_json
    from navkit.io.trajectory import read_tum

    out, _, _ = outputs
    tr = read_tum(out / "truth.tum")
    np.testing.assert_allclose(tr.positions[:, :2], mission_run.truth[:, :2], atol=1e-9)
    spline = read_path_json(out / "path.json")
    assert spline.total_length == pytest.approx(mission_run.path.total_length, rel=1e-9)
    grid = read_occupancy_grid(out / "obstacle_map.yaml")
    occ = np.asarray(grid.occupancy)
    assert (occ == 100).sum() == mission_run.obstacle_grid.occupied.sum()


def test_report_renders_in_headless_chromium(outputs, tmp_path):
    import cv2

    from tests.viz.browser import open_page

    out, _, _ = outputs
    result = open_page(out / "report.html", tmp_path / "shot.png", size=(1280, 3000))
    assert result.console_errors == []
    shot = cv2.imread(str(result.screenshot))
    assert shot is not None and shot.shape[0] >= 2000
    # figures, not a blank page: the figures have white backgrounds, but their lines, patches
    # and text still cover several percent of the page (a page of text only: well under 2 %),
    # and the trajectory colours (matplotlib tab:green (44, 160, 44), tab:red (214, 39, 40)) show
    nonwhite = (shot < 235).any(axis=2).mean()
    assert nonwhite > 0.05
    b, g, r = (shot[..., i].astype(int) for i in range(3))
    green = (abs(r - 44) < 30) & (abs(g - 160) < 30) & (abs(b - 44) < 30)
    red = (abs(r - 214) < 30) & (abs(g - 39) < 30) & (abs(b - 40) < 30)
    assert green.sum() > 300 and red.sum() > 300


def test_cli_mission_run_on_a_users_scene(cli, tmp_path):
    scene_file = tmp_path / "tiny.toml"
    scene_file.write_text(scene_to_toml(small_scene()))
    (tmp_path / "tiny.mission.toml").write_text(
        "[route]\nwaypoints = [[0.0, 0.0], [3.0, 0.0]]\n\n[settings]\nseed = 5\n"
        "[settings.lidar]\nn_beams = 16\nn_columns = 360\n"
    )
    out = tmp_path / "out"
    config = tmp_path / "config.toml"  # --config: the [mission] table of a settings.toml
    config.write_text("[mission.obstacle_map]\nmatch_tolerance = 0.55\n[route]\nignored = 1\n")
    rrd = tmp_path / "mission.rrd"
    args = ("--out", out, "--small", "--config", config, "--rerun-save", rrd)
    res = cli("mission", "run", scene_file, *args)
    assert res.exit_code == 0, res.output
    assert "from the operator" in res.output
    summary = json.loads((out / "summary.json").read_text())
    metrics = json.loads((out / "metrics.json").read_text())
    assert summary["outcome"] == metrics["return"]["outcome"] == "returned"
    assert (
        summary["final_distance_to_operator_m"] == metrics["return"]["final_distance_to_operator_m"]
    )
    settings = (out / "settings.toml").read_text()
    assert "seed = 5" in settings and "n_beams = 16" in settings
    assert "match_tolerance = 0.55" in settings
    assert (out / "report.html").is_file()
    # the runtime's results: one estimate pose per control step, as in estimate.tum; the .rrd
    assert "results.mcap" in summary["outputs"] and rrd.stat().st_size > 0
    from navkit.io.results_mcap import read_messages

    est = [
        r.message.pose.position for r in read_messages(out / "results.mcap", ["/navkit/estimate"])
    ]
    tum = np.loadtxt(out / "estimate.tum", comments="#")
    np.testing.assert_allclose([[p.x, p.y] for p in est], tum[:, 1:3], atol=1e-9)
    # the outputs of a run are not overwritten silently
    before = (out / "summary.json").read_text()
    res = cli("mission", "run", scene_file, "--out", out, "--small")
    assert (
        res.exit_code == 2 and "already holds outputs" in res.output and "--overwrite" in res.output
    )
    assert (out / "summary.json").read_text() == before


def test_cli_mission_run_without_a_route_is_a_clear_error(cli, tmp_path):
    scene_file = tmp_path / "noroute.toml"
    scene_file.write_text(scene_to_toml(small_scene()))
    res = cli("mission", "run", scene_file, "--out", tmp_path / "o")
    assert res.exit_code == 2
    assert "noroute.mission.toml" in res.output and "waypoints" in res.output
    assert not (tmp_path / "o" / "report.html").exists()


def test_cli_mission_run_with_a_bad_mission_file(cli, tmp_path):
    scene_file = tmp_path / "s.toml"
    scene_file.write_text(scene_to_toml(small_scene()))
    bad = tmp_path / "bad_mission.toml"
    bad.write_text("[route]\nwaypoints = [[0, 0], [3, 0]]\n[settings.lidar]\nbeams = 3\n")
    res = cli("mission", "run", scene_file, "--mission", bad, "--out", tmp_path / "o")
    assert res.exit_code == 2
    assert "bad_mission.toml" in res.output and "lidar.beams" in res.output
    assert Path(tmp_path / "o").exists() is False or not (tmp_path / "o" / "report.html").exists()
