"""``navkit run`` on real recordings written as ROS bags in the test (rosbags' writers):
SemanticKITTI clouds + poses (ROS 2 mcap storage and ROS 1), a CARMEN log (LaserScan + Odometry)."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("rosbags", reason="rosbags (extra 'ros') not installed")
pytest.importorskip("mcap", reason="mcap (extra 'ros') not installed")

from navkit.io.results_mcap import read_messages
from tests.runtime.bags import split_carmen, write_carmen_bag, write_kitti_bag

pytestmark = pytest.mark.realdata

REPO = Path(__file__).resolve().parents[2]
EVERY = 2  # localize every 2nd scan of the log's second half (as map locate --every 2)


def _records(out: Path, capability: str) -> list[dict]:
    lines = (out / "frames.jsonl").read_text().splitlines()
    return [r for r in map(json.loads, lines) if r["capability"] == capability]


# --------------------------------------------------------------------------- SemanticKITTI
@pytest.fixture(scope="module")
def kitti(tmp_path_factory):
    from navkit import datasets
    from navkit.errors import DataNotFoundError

    try:
        folder = datasets.find("lidar/semantickitti-seq00")
    except DataNotFoundError as exc:
        pytest.skip(f"recorded data absent: {exc}")
    d = tmp_path_factory.mktemp("kitti")
    bins = write_kitti_bag(folder, d / "kitti_ros2", ros1=False)
    write_kitti_bag(folder, d / "kitti.bag", ros1=True)
    return folder, bins, d


@pytest.mark.parametrize("bag", ["kitti_ros2", "kitti.bag"])
def test_obstacles_equal_obstacles_detect(kitti, bag, cli):
    """Per frame, the run's labels and obstacle counts equal ``navkit obstacles detect``'s."""
    _folder, bins, d = kitti
    ref = d / "detect"
    if not ref.exists():
        r = cli("obstacles", "detect", *bins, "--out", ref)
        assert r.exit_code == 0, r.output
    out = d / f"run_{bag}"
    r = cli("run", d / bag, "--out", out)
    assert r.exit_code == 0, r.output
    recs = _records(out, "obstacles")
    assert len(recs) == len(bins)
    for k, b in enumerate(bins):
        want = np.load(ref / b.stem / "labels.npy")
        got = np.load(out / "obstacles" / f"{k:06d}" / "labels.npy")
        np.testing.assert_array_equal(got, want)
        ref_json = json.loads((ref / b.stem / "obstacles.json").read_text())
        run_json = json.loads((out / "obstacles" / f"{k:06d}" / "obstacles.json").read_text())
        assert len(run_json["obstacles"]) == len(ref_json["obstacles"]) == recs[k]["n_obstacles"]
        assert [o["n_points"] for o in run_json["obstacles"]] == [
            o["n_points"] for o in ref_json["obstacles"]
        ]
    summary = json.loads((out / "summary.json").read_text())
    assert set(summary["capabilities"]) == {"obstacles", "path"}
    assert summary["capabilities"]["obstacles"]["map_scans"] == len(bins)
    assert summary["capabilities"]["obstacles"]["real_time_factor"] > 0


def test_results_mcap_kitti(kitti, cli):
    """results.mcap: standard types, counts, frame ids and the recording's stamps."""
    folder, bins, d = kitti
    out = d / "run_kitti_ros2"
    if not out.exists():
        assert cli("run", d / "kitti_ros2", "--out", out).exit_code == 0
    times = np.loadtxt(next(folder.glob("times*.txt")))[: len(bins)]
    stamps = [round(t * 1e9) + 1_000_000_000 for t in times]
    msgs = list(read_messages(out / "results.mcap"))
    by_topic: dict[str, list] = {}
    for m in msgs:
        by_topic.setdefault(m.topic, []).append(m)
    pts = by_topic["/navkit/obstacles/points"]
    assert [m.msgtype for m in pts] == ["sensor_msgs/msg/PointCloud2"] * len(bins)
    assert [m.log_time_ns for m in pts] == stamps
    for k, m in enumerate(pts):
        h = m.message.header
        assert h.frame_id == "velodyne"
        assert h.stamp.sec * 1_000_000_000 + h.stamp.nanosec == stamps[k]
        assert [f.name for f in m.message.fields] == ["x", "y", "z", "class"]
        rec = np.frombuffer(
            m.message.data.tobytes(),
            dtype=np.dtype(
                {
                    "names": ["x", "class"],
                    "formats": ["<f4", "i1"],
                    "offsets": [0, 12],
                    "itemsize": 16,
                }
            ),
        )
        want = np.load(out / "obstacles" / f"{k:06d}" / "labels.npy")
        np.testing.assert_array_equal(rec["class"], want)
        xyz = np.fromfile(bins[k], dtype="<f4").reshape(-1, 4)
        np.testing.assert_array_equal(rec["x"], xyz[:, 0])
    shapes = by_topic["/navkit/obstacles/shapes"]
    assert len(shapes) == len(bins)
    assert shapes[0].msgtype == "visualization_msgs/msg/MarkerArray"
    assert shapes[0].message.markers[0].action == 3  # DELETEALL, then the outlines
    n_obst = [r["n_obstacles"] for r in _records(out, "obstacles")]
    from navkit.runtime.capabilities import SHAPE_COLORS

    for m, n in zip(shapes, n_obst, strict=True):
        # one LINE_LIST: A1 (a rectangle, 4 segments) and A6 of every obstacle, coloured per
        # vertex by shape
        assert len(m.message.markers) == 2 and m.message.markers[1].type == 5
        mk = m.message.markers[1]
        assert mk.header.frame_id == "velodyne" and len(mk.points) == len(mk.colors)
        assert len(mk.points) % 2 == 0
        rgba = np.array([[c.r, c.g, c.b, c.a] for c in mk.colors])
        a1 = np.all(np.isclose(rgba, SHAPE_COLORS["A1"]), axis=1)
        a6 = np.all(np.isclose(rgba, SHAPE_COLORS["A6"]), axis=1)
        assert (a1 | a6).all()
        assert a1.sum() == 2 * 4 * n  # two ends per segment
    grid = by_topic["/navkit/obstacle_map"][-1]
    assert grid.msgtype == "nav_msgs/msg/OccupancyGrid" and grid.message.header.frame_id == "odom"
    info = grid.message.info
    assert len(grid.message.data) == info.width * info.height
    assert (grid.message.data == 100).sum() == json.loads((out / "summary.json").read_text())[
        "capabilities"
    ]["obstacles"]["map_cells_occupied"]
    path = by_topic["/navkit/path"][-1]
    assert path.msgtype == "nav_msgs/msg/Path" and len(path.message.poses) >= 2
    # the standard tooling reads it too: mcap's indexed reader and mcap-ros2-support's decoder
    # (which parses the ros2msg schemas navkit wrote)
    pytest.importorskip("mcap_ros2", reason="mcap-ros2-support (extra 'ros') not installed")
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    with open(out / "results.mcap", "rb") as fh:
        reader = make_reader(fh, decoder_factories=[DecoderFactory()])
        summary = reader.get_summary()
        assert summary is not None and summary.statistics.message_count == len(msgs)
        assert {s.name for s in summary.schemas.values()} == {
            "tf2_msgs/msg/TFMessage",
            "sensor_msgs/msg/PointCloud2",
            "visualization_msgs/msg/MarkerArray",
            "nav_msgs/msg/OccupancyGrid",
            "nav_msgs/msg/Path",
        }
        decoded = list(reader.iter_decoded_messages(topics=["/navkit/obstacles/points"]))
    assert [d.message.log_time for d in decoded] == stamps
    assert decoded[0].decoded_message.width == len(np.fromfile(bins[0], dtype="<f4")) // 4


def test_rerun_recording_loads(kitti, tmp_path):
    """--rerun-save writes an .rrd that Rerun's own verifier loads."""
    pytest.importorskip("rerun", reason="rerun-sdk (extra 'rerun') not installed")
    _folder, _bins, d = kitti
    rrd = tmp_path / "run.rrd"
    env = {**os.environ, "PYTHONPATH": str(REPO / "src"), "RERUN_ANALYTICS": "0"}
    r = subprocess.run(
        [
            sys.executable,
            "-m",
            "navkit",
            "run",
            str(d / "kitti_ros2"),
            "-o",
            str(tmp_path / "o"),
            "--rerun-save",
            str(rrd),
        ],
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert r.returncode == 0, r.stderr
    assert rrd.stat().st_size > 100_000
    rerun_exe = Path(sys.executable).with_name("rerun")
    if not rerun_exe.exists():
        pytest.skip("the rerun executable is not installed beside python")
    v = subprocess.run(
        [str(rerun_exe), "rrd", "verify", str(rrd)],
        capture_output=True,
        text=True,
        timeout=120,
        env=env,
    )
    assert v.returncode == 0, v.stderr
    s = subprocess.run(
        [str(rerun_exe), "rrd", "stats", str(rrd)],
        capture_output=True,
        text=True,
        timeout=120,
        env=env,
    )
    assert s.returncode == 0
    text = s.stdout + s.stderr
    assert "obstacles/points" in text and "num_chunks" in text


# --------------------------------------------------------------------------- CARMEN
@pytest.fixture(scope="module")
def carmen(tmp_path_factory, cli):
    from navkit import datasets
    from navkit.errors import DataNotFoundError

    try:
        log_gz = datasets.find("laser2d/freiburg-101-corrected.log.gz")
    except DataNotFoundError as exc:
        pytest.skip(f"recorded data absent: {exc}")
    d = tmp_path_factory.mktemp("carmen")
    first, second = split_carmen(log_gz, d)
    n = write_carmen_bag(second, d / "second.bag", ros1=True, every=EVERY)
    write_carmen_bag(first, d / "first_ros2", ros1=False)
    assert cli("map", "build", first, "--out", d / "map").exit_code == 0
    r = cli(
        "map",
        "locate",
        d / "map" / "map.json",
        second,
        "--out",
        d / "locate",
        "--prior",
        "odometry",
        "--every",
        str(EVERY),
    )
    assert r.exit_code == 0, r.output
    (d / "cfg.toml").write_text("[run]\ncheckpoint_every = 10\n")
    out = d / "run"
    r = cli(
        "run",
        d / "second.bag",
        "--map",
        d / "map" / "map.json",
        "--config",
        d / "cfg.toml",
        "--out",
        out,
    )
    assert r.exit_code == 0, r.output
    return d, n


@pytest.fixture(scope="module")
def cli():
    from typer.testing import CliRunner

    from navkit.cli.main import app

    runner = CliRunner()
    return lambda *a: runner.invoke(app, [str(x) for x in a], catch_exceptions=False)


def test_localization_scores_like_map_locate(carmen):
    """Against a map built from the log's first half, the run localizes the second half like
    ``map locate --prior odometry`` (ranges are float32 in a LaserScan: measured difference of
    the median error 3e-5 m on freiburg-101; tolerance 5 mm)."""
    d, n = carmen
    ref = json.loads((d / "locate" / "summary.json").read_text())
    run = json.loads((d / "run" / "summary.json").read_text())["capabilities"]["localization"]
    assert run["fixes"] == ref["fixes"] == n
    assert abs(run["position_error_m_median"] - ref["position_error_m_median"]) < 0.005
    assert abs(run["success_rate"] - ref["success_rate"]) <= 2 / n
    assert run["position_error_m_median"] < 0.2  # the map's own accuracy: about 0.1 m here
    poses = [
        m
        for m in read_messages(d / "run" / "results.mcap")
        if m.topic == "/navkit/localization/pose"
    ]
    # only accepted fixes are poses (a LocalizationFailure is a record, never a result)
    assert len(poses) == round(run["ok_rate"] * n)
    assert poses[0].msgtype == "geometry_msgs/msg/PoseWithCovarianceStamped"
    assert {p.message.header.frame_id for p in poses} == {"map"}
    stamps = [p.log_time_ns for p in poses]
    assert stamps == sorted(stamps)


def test_localization_is_the_localizer(carmen):
    """The run's fixes are ``localization.Localizer``'s (the object of ``map locate``) on the
    scans as the bag holds them: ranges, ``angle_min`` and ``angle_increment`` rounded to float32
    (with the log's float64 scans, ``map locate`` differs on 1 of 73 scans in acceptance and by
    0.5 mm median, 18 mm at most in position on freiburg-101: the matcher's discrete search)."""
    from navkit.io.carmen import read_carmen
    from navkit.io.scan_sequence import read_scan_sequence
    from navkit.io.wallmap import read_wall_map
    from navkit.localization import Fix, Localizer

    d, n = carmen
    seq = read_scan_sequence(d / "second.log", every=EVERY)
    lg = read_carmen(d / "second.log")
    nb = lg.ranges.shape[1]
    step = np.float32((lg.bearings[-1] - lg.bearings[0]) / (nb - 1))
    bearings = float(np.float32(lg.bearings[0])) + np.arange(nb) * float(step)
    loc = Localizer(read_wall_map(d / "map" / "map.json"))
    recs = _records(d / "run", "localization")
    assert len(recs) == len(seq) == n
    for k, rec in enumerate(recs):
        r = lg.ranges[seq.indices[k]].astype(np.float32).astype(np.float64)
        ok = np.isfinite(r) & (r < 30.0)
        pts = np.c_[r[ok] * np.cos(bearings[ok]), r[ok] * np.sin(bearings[ok])]
        fix = loc.update(pts, odometry_delta=seq.odometry_delta(k))
        assert rec["ok"] == isinstance(fix, Fix) and rec["reason"] == fix.reason
        if isinstance(fix, Fix):
            np.testing.assert_allclose([rec["x"], rec["y"], rec["theta"]], fix.pose, atol=1e-9)


def test_wall_map_from_scans_and_poses(carmen, cli):
    """Without --map, LaserScan + poses build the wall map as ``navkit map build`` does."""
    d, _ = carmen
    out = d / "wallmap"
    assert cli("run", d / "first_ros2", "--out", out).exit_code == 0
    ref = json.loads((d / "map" / "map.json").read_text())
    got = json.loads((out / "wall_map" / "map.json").read_text())
    assert len(got["walls"]) == len(ref["walls"])
    grids = [m for m in read_messages(out / "results.mcap") if m.topic == "/navkit/wall_map"]
    assert len(grids) == 1 and grids[0].msgtype == "nav_msgs/msg/OccupancyGrid"
    np.testing.assert_allclose(
        [w["start"] for w in got["walls"]], [w["start"] for w in ref["walls"]], atol=1e-4
    )
    # the CARMEN log itself, streamed scan by scan: the same map (float64 ranges; the poses
    # pass through 4x4 matrices, so equal to rounding)
    assert cli("run", d / "first.log", "--out", d / "wallmap_log").exit_code == 0
    log_map = json.loads((d / "wallmap_log" / "wall_map" / "map.json").read_text())
    assert len(log_map["walls"]) == len(ref["walls"])
    for key in ("start", "end"):
        np.testing.assert_allclose(
            [w[key] for w in log_map["walls"]], [w[key] for w in ref["walls"]], atol=1e-9
        )


def _strip(rec: dict) -> dict:
    return {k: v for k, v in rec.items() if k not in ("ms", "motion_ms")}


def test_kill_and_resume(carmen, tmp_path):
    """SIGKILL halfway: frames.jsonl holds complete lines only, the closed segments are valid
    MCAP; --resume finishes with the same results as the uninterrupted run."""
    d, n = carmen
    out = tmp_path / "killed"
    args = [
        sys.executable,
        "-m",
        "navkit",
        "run",
        str(d / "second.bag"),
        "--map",
        str(d / "map" / "map.json"),
        "--config",
        str(d / "cfg.toml"),
        "--out",
        str(out),
    ]
    env = {**os.environ, "PYTHONPATH": str(REPO / "src")}
    proc = subprocess.Popen(args, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    frames = out / "frames.jsonl"
    t0 = time.monotonic()
    try:
        while time.monotonic() - t0 < 120:
            if frames.exists() and frames.read_text().count('"localization"') >= n // 2:
                break
            if proc.poll() is not None:
                pytest.fail("the run ended before it could be killed")
            time.sleep(0.05)
        proc.send_signal(signal.SIGKILL)
    finally:
        proc.wait(timeout=30)
    assert not (out / "results.mcap").exists() and not (out / "summary.json").exists()
    lines = frames.read_text().splitlines()
    killed = [json.loads(x) for x in lines]  # every line complete
    done = [r for r in killed if r["capability"] == "localization"]
    assert n // 2 <= len(done) < n
    full = _records(d / "run", "localization")
    assert [_strip(r) for r in done] == [_strip(r) for r in full[: len(done)]]
    from mcap.reader import make_reader

    segs = sorted((out / ".navkit-run" / "segments").glob("*.mcap"))
    assert len(segs) >= 2
    for seg in segs[:-1]:
        with open(seg, "rb") as fh:
            summary = make_reader(fh).get_summary()
            assert summary is not None and summary.statistics is not None
    r = subprocess.run([*args, "--resume"], env=env, capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    resumed = _records(out, "localization")
    assert [_strip(x) for x in resumed] == [_strip(x) for x in full]
    a = [
        (m.log_time_ns, m.message.pose.pose.position.x, m.message.pose.pose.position.y)
        for m in read_messages(out / "results.mcap")
        if m.topic == "/navkit/localization/pose"
    ]
    b = [
        (m.log_time_ns, m.message.pose.pose.position.x, m.message.pose.pose.position.y)
        for m in read_messages(d / "run" / "results.mcap")
        if m.topic == "/navkit/localization/pose"
    ]
    assert a == b
    s = json.loads((out / "summary.json").read_text())
    assert s["resumed"] and s["capabilities"]["localization"]["fixes"] == n


def test_ctrl_c_and_resume(carmen, tmp_path):
    """SIGINT halfway: the run stops after the current item with a checkpoint, exits 130 and
    says how to continue; --resume then gives the records and poses of the uninterrupted run."""
    d, n = carmen
    out = tmp_path / "interrupted"
    args = [
        sys.executable,
        "-m",
        "navkit",
        "run",
        str(d / "second.bag"),
        "--map",
        str(d / "map" / "map.json"),
        "--config",
        str(d / "cfg.toml"),
        "--out",
        str(out),
    ]
    env = {**os.environ, "PYTHONPATH": str(REPO / "src")}
    proc = subprocess.Popen(
        args, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True
    )
    frames = out / "frames.jsonl"
    t0 = time.monotonic()
    try:
        while time.monotonic() - t0 < 120:
            if frames.exists() and frames.read_text().count('"localization"') >= n // 2:
                break
            if proc.poll() is not None:
                pytest.fail("the run ended before it could be interrupted")
            time.sleep(0.05)
        proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 130, err
    assert "--resume" in err and "no output was changed" not in err, err
    assert (out / ".navkit-run" / "checkpoint.pkl").is_file()
    assert not (out / "results.mcap").exists() and not (out / "summary.json").exists()
    done = [json.loads(x) for x in frames.read_text().splitlines()]
    assert n // 2 <= len([r for r in done if r["capability"] == "localization"]) < n
    r = subprocess.run([*args, "--resume"], env=env, capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    full = _records(d / "run", "localization")
    assert [_strip(x) for x in _records(out, "localization")] == [_strip(x) for x in full]

    def poses(folder: Path) -> list[tuple[int, float, float]]:
        return [
            (m.log_time_ns, m.message.pose.pose.position.x, m.message.pose.pose.position.y)
            for m in read_messages(folder / "results.mcap")
            if m.topic == "/navkit/localization/pose"
        ]

    assert poses(out) == poses(d / "run")
    assert not (out / ".navkit-run").exists()
