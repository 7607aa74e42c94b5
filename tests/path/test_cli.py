"""``navkit path record | return | simulate`` on simulated and real trajectories, and bad input."""

from __future__ import annotations

import json

import numpy as np
import pytest

from navkit.io.pathjson import read_path_json


def test_simulate_record_return(cli, tmp_path):
    sim = tmp_path / "sim"
    r = cli("path", "simulate", "--out", sim, "--legs", "5", "--seed", "1")
    assert r.exit_code == 0, r.output
    rec = tmp_path / "rec"
    r = cli("path", "record", sim / "vo.tum", "--tolerance", "0.01", "--out", rec)
    assert r.exit_code == 0, r.output
    for name in ("path.json", "path.png", "summary.json", "settings.toml"):
        assert (rec / name).stat().st_size > 0
    summary = json.loads((rec / "summary.json").read_text())
    assert summary["max_deviation_m"] <= 0.01
    spline = read_path_json(rec / "path.json")
    # the VO track of 5 legs of 0.5 m: its length is 2.5 m up to the VO's 2 % scale noise
    assert spline.total_length == pytest.approx(2.5, rel=0.1)
    assert spline.frame["kind"] == "plane"
    out = tmp_path / "ret"
    r = cli("path", "return", rec / "path.json", "--runs", "6", "--out", out, "--seed", "3")
    assert r.exit_code == 0, r.output
    ret = json.loads((out / "returns.json").read_text())
    assert ret["runs"] == 6 and len(ret["runs_detail"]) == 6
    assert ret["final_error_mean_pct"] < 16.0
    assert (out / "returns.png").stat().st_size > 0


@pytest.mark.realdata
def test_record_kitti(cli, tmp_path, data_path):
    r = cli(
        "path", "record", data_path("trajectories/KITTI_00_gt.txt"), "--tolerance", "0.5",
        "--out", tmp_path / "k",
    )  # fmt: skip
    assert r.exit_code == 0, r.output
    s = json.loads((tmp_path / "k" / "summary.json").read_text())
    assert s["points"] == 4541 and s["max_deviation_m"] <= 0.5
    assert s["loops_removed"] >= 1  # KITTI 00 drives several blocks twice


def test_record_odometry_log(cli, tmp_path):
    """A 'time v omega' log (MRCLAM layout, with a comment header) is detected and integrated:
    constant v = 0.2 m/s and omega = 0.1 rad/s for 20 s is an arc of radius 2 m, length 4 m."""
    f = tmp_path / "Robot_Odometry.dat"
    t = np.arange(0.0, 20.0 + 1e-9, 0.01)
    lines = "".join(f"{ti:.2f} 0.2 0.1\n" for ti in t)
    f.write_text("# Time [s]   v [m/s]   omega [rad/s]\n" + lines)
    r = cli("path", "record", f, "--tolerance", "0.01", "--keep-loops", "--out", tmp_path / "m")
    assert r.exit_code == 0, r.output
    s = json.loads((tmp_path / "m" / "summary.json").read_text())
    assert s["format"] == "odometry" and s["loops_removed"] == 0
    spline = read_path_json(tmp_path / "m" / "path.json")
    # the last sample's command is not integrated (zero-order hold): 19.99 s of motion. A curve
    # within eps of an arc differs in length by at most ~eps x the turned angle (an offset
    # curve at distance d has length L + d dtheta): 0.01 m x 2 rad = 2 cm
    assert spline.total_length == pytest.approx(0.2 * 19.99, abs=0.02)
    end = spline.position(spline.total_length)
    th = 0.1 * 19.99
    np.testing.assert_allclose(end, [2.0 * np.sin(th), 2.0 * (1 - np.cos(th))], atol=0.01)


@pytest.mark.parametrize(
    ("content", "message"),
    [
        ("0 1 2 3 0 0 0 1\n", "zero length"),  # a single pose
        ("0 1 2 3 0 0 0 1\n1 1 2 3 0 0 0 1\n2 1 2 3 0 0 0 1\n", "zero length"),  # no motion
        ("0 1 2 3 0 0 0 1\n1 nan 2 3 0 0 0 1\n", "error:"),  # NaN pose
        (
            "0 0 0 0 0 0 0 1\n2 1 0 0 0 0 0 1\n1 2 0 0 0 0 0 1\n",
            "before the previous",
        ),  # time backwards
        ("0 0 0\n", "error:"),  # an odometry log with one sample
        ("hello world\n", "error:"),
    ],
)
def test_bad_trajectories_fail_cleanly(cli, tmp_path, content, message):
    f = tmp_path / "traj.txt"
    f.write_text(content)
    out = tmp_path / "out"
    r = cli("path", "record", f, "--out", out)
    assert r.exit_code == 2
    assert message in r.output
    assert "Traceback" not in r.output
    assert not (out / "path.json").exists()


def test_missing_and_bad_path_json(cli, tmp_path):
    r = cli("path", "return", tmp_path / "nope.json", "--out", tmp_path / "o")
    assert r.exit_code == 2 and "no such" in r.output
    bad = tmp_path / "path.json"
    bad.write_text('{"segments": [{"s0": 0}]}')
    r = cli("path", "return", bad, "--out", tmp_path / "o")
    assert r.exit_code == 2 and "segments[0]" in r.output
    assert not (tmp_path / "o" / "returns.json").exists()


def test_bad_options(cli, tmp_path):
    f = tmp_path / "t.txt"
    f.write_text("".join(f"{i} {i * 0.1} 0 0 0 0 0 1\n" for i in range(10)))
    r = cli("path", "record", f, "--tolerance", "-1", "--out", tmp_path / "o")
    assert r.exit_code == 2 and "tolerance" in r.output
    r = cli(
        "path", "record", f, "--plane", "xz", "--out", tmp_path / "o"
    )  # x and z: a line along x
    assert r.exit_code == 0, r.output
    assert np.isclose(read_path_json(tmp_path / "o" / "path.json").total_length, 0.9)


def test_record_euroc_csv_on_a_tilted_plane(cli, tmp_path):
    """A EuRoC ground-truth CSV whose positions lie on a plane tilted 30 deg about x: the auto
    ground plane recovers in-plane distances, so a 1 m-radius half circle is 3.14 m long."""
    n = 400
    th = np.linspace(0.0, np.pi, n)
    u, v = np.sin(th), 1.0 - np.cos(th)  # in-plane circle of radius 1
    c, s = np.cos(np.radians(30)), np.sin(np.radians(30))
    xyz = np.c_[u, c * v, s * v] + [2.0, -1.0, 0.5]
    ns = 1_403_636_579_758_555_392 + np.arange(n) * 5_000_000
    header = "#timestamp [ns],p_RS_R_x [m],p_RS_R_y [m],p_RS_R_z [m],q_RS_w [],q_RS_x [],q_RS_y [],q_RS_z []\n"
    rows = "".join(
        f"{t},{x:.9f},{y:.9f},{z:.9f},1,0,0,0\n" for t, (x, y, z) in zip(ns, xyz, strict=True)
    )
    f = tmp_path / "data.csv"
    f.write_text(header + rows)
    r = cli("path", "record", f, "--tolerance", "0.005", "--out", tmp_path / "e")
    assert r.exit_code == 0, r.output
    spline = read_path_json(tmp_path / "e" / "path.json")
    # within eps = 5 mm of a half circle: length within eps x turned angle (pi) of pi
    assert spline.total_length == pytest.approx(np.pi, abs=0.005 * np.pi)
    assert spline.frame["method"] == "fit" and spline.frame["rms_m"] < 1e-6
