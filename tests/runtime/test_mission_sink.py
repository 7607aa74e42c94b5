"""The mission through the runtime's sinks: the small test world's mission with
:class:`navkit.runtime.mission_sink.MissionSink` writes ``results.mcap`` (read back with
``mcap``) and an ``.rrd`` (verified with ``rerun rrd verify``); both against the mission's own
log, and the mission's figures are the ones of a run without a sink."""

from __future__ import annotations

import subprocess
import sys
from collections import defaultdict

import numpy as np
import pytest

from tests.mission.conftest import small_route, small_scene

pytest.importorskip("mcap")
pytest.importorskip("rosbags")


@pytest.fixture(scope="module")
def sunk(tmp_path_factory):
    """The conftest's ``mission_run`` scenario (small world, seed 3) with the sink and Rerun."""
    pytest.importorskip("rerun")
    from navkit.mission import MissionSettings, run_mission
    from navkit.runtime.mission_sink import MissionSink
    from navkit.viz.rerun_logger import RerunLogger

    out = tmp_path_factory.mktemp("mission_sink")
    sink = MissionSink(out, RerunLogger(save=out / "mission.rrd"))
    lg = run_mission(small_scene(), small_route(), MissionSettings.small(seed=3), None, sink.step)
    files = sink.finish(lg)
    return out, lg, files, sink


@pytest.fixture(scope="module")
def plain():
    """The same mission without a sink."""
    from navkit.mission import MissionSettings, run_mission

    return run_mission(small_scene(), small_route(), MissionSettings.small(seed=3))


def _read(path):
    """Every message with the mcap reader itself (schema name, encoding, log time, decoded)."""
    from mcap.reader import make_reader
    from rosbags.typesys import Stores, get_typestore

    ts = get_typestore(Stores.LATEST)
    by_topic = defaultdict(list)
    with open(path, "rb") as fh:
        reader = make_reader(fh)
        assert reader.get_header().profile == "ros2"
        for schema, channel, message in reader.iter_messages(log_time_order=False):
            assert schema.encoding == "ros2msg" and channel.message_encoding == "cdr"
            msg = ts.deserialize_cdr(message.data, schema.name)
            by_topic[channel.topic].append((schema.name, message.log_time, msg))
    return by_topic


def test_mission_results_mcap_reads_back_against_the_log(sunk, plain):
    out, lg, files, sink = sunk
    assert files == ["results.mcap"]
    # the sink changes nothing in the mission: same trajectory, outcome and stored path as the
    # same mission without a sink
    assert lg.outcome == plain.outcome == "returned"
    np.testing.assert_array_equal(lg.estimate, plain.estimate)
    np.testing.assert_array_equal(lg.truth, plain.truth)

    got = _read(out / "results.mcap")
    types = {t: {m[0] for m in msgs} for t, msgs in got.items()}
    assert types == {
        "/navkit/obstacles/points": {"sensor_msgs/msg/PointCloud2"},
        "/navkit/obstacles/shapes": {"visualization_msgs/msg/MarkerArray"},
        "/navkit/obstacle_map": {"nav_msgs/msg/OccupancyGrid"},
        "/navkit/localization/pose": {"geometry_msgs/msg/PoseStamped"},
        "/navkit/planes/pose": {"geometry_msgs/msg/PoseStamped"},
        "/navkit/path": {"nav_msgs/msg/Path"},
        "/navkit/return_path": {"nav_msgs/msg/Path"},
        "/navkit/estimate": {"geometry_msgs/msg/PoseStamped"},
        "/navkit/truth": {"geometry_msgs/msg/PoseStamped"},
        "/navkit/walls": {"visualization_msgs/msg/MarkerArray"},
    }
    assert sum(len(v) for v in got.values()) == sink.n_messages
    # log times: the stamps (simulated time), never decreasing in file order within a topic,
    # and equal to the header stamps
    for topic, msgs in got.items():
        t = np.array([m[1] for m in msgs])
        assert np.all(np.diff(t) >= 0), topic
        if topic not in ("/navkit/obstacles/shapes", "/navkit/walls"):
            hs = np.array([m[2].header.stamp.sec * 10**9 + m[2].header.stamp.nanosec for m in msgs])
            np.testing.assert_array_equal(hs, t)

    # counts: one estimate and truth pose per control step, one cloud + shapes per lidar scan,
    # one plane pose per RGB-D frame, one pose per fix the matcher accepted
    n_steps = len(lg.time)
    assert len(got["/navkit/estimate"]) == len(got["/navkit/truth"]) == n_steps
    every_lidar = lg.settings.every(lg.settings.lidar.rate_hz)
    n_scans = (n_steps - 1) // every_lidar
    assert len(got["/navkit/obstacles/points"]) == len(got["/navkit/obstacles/shapes"]) == n_scans
    assert len(got["/navkit/planes/pose"]) == len(lg.plane_steps)
    n_ok = sum(f.ok and np.all(np.isfinite(f.pose)) for f in (*lg.fixes, *lg.map_fixes))
    assert n_ok > 0 and len(got["/navkit/localization/pose"]) == n_ok

    # poses: the log's estimate and truth (x, y, yaw), to float64 round-off
    est = np.array(
        [
            [m.pose.position.x, m.pose.position.y, _yaw(m.pose.orientation)]
            for _, _, m in got["/navkit/estimate"]
        ]
    )
    np.testing.assert_allclose(est[:, :2], lg.estimate[:, :2], atol=1e-9)
    np.testing.assert_allclose(np.cos(est[:, 2] - lg.estimate[:, 2]), 1.0, atol=1e-12)
    tru = np.array([[m.pose.position.x, m.pose.position.y] for _, _, m in got["/navkit/truth"]])
    np.testing.assert_allclose(tru, lg.truth[:, :2], atol=1e-9)
    np.testing.assert_allclose(
        [t * 1e-9 for _, t, _ in got["/navkit/estimate"]], lg.time, atol=1e-9
    )

    # the last stored path is the log's spline sampled every 0.1 m (float64 in the message)
    _, xy = lg.path.sample(0.1)
    last = got["/navkit/path"][-1][2]
    P = np.array([[p.pose.position.x, p.pose.position.y] for p in last.poses])
    np.testing.assert_allclose(P, xy, atol=1e-12)
    # the return path: the estimate on the way back
    ret = got["/navkit/return_path"][-1][2]
    R = np.array([[p.pose.position.x, p.pose.position.y] for p in ret.poses])
    np.testing.assert_allclose(R, lg.estimate[lg.phase == 1][:, :2], atol=1e-12)

    # the final obstacle map is the log's mapper (-1 unseen, 0 free, 100 occupied)
    g = got["/navkit/obstacle_map"][-1][2]
    occ = np.asarray(g.data, np.int8).reshape(g.info.height, g.info.width)
    m = lg.obstacle_grid
    assert occ.shape == m.occupied.shape
    np.testing.assert_array_equal(occ == 100, m.occupied)
    np.testing.assert_array_equal(occ >= 0, m.seen > 0)
    np.testing.assert_allclose([g.info.origin.position.x, g.info.origin.position.y], m.origin)

    # clouds: x y z float32 + class int8; classes of paper 1 only, obstacles present
    classes = []
    for _, _, c in got["/navkit/obstacles/points"]:
        names = [f.name for f in c.fields]
        assert names == ["x", "y", "z", "class"] and c.point_step == 16
        rec = np.frombuffer(
            bytes(c.data),
            dtype=[("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("class", "i1"), ("p", "V3")],
        )
        assert len(rec) == c.width and np.isfinite(rec["x"]).all()
        classes.append(rec["class"])
    cls = np.concatenate(classes)
    assert (
        set(np.unique(cls)) <= {0, -1, -2, -3, -4}
        and (cls == -2).sum() > 0
        and (cls == 0).sum() > 0
    )


def _yaw(q):
    return np.arctan2(2 * (q.w * q.z + q.x * q.y), 1 - 2 * (q.y**2 + q.z**2))


def test_mission_rrd_loads_back(sunk):
    out = sunk[0]
    rrd = out / "mission.rrd"
    assert rrd.stat().st_size > 0
    res = subprocess.run(
        [sys.executable, "-m", "rerun", "rrd", "verify", str(rrd)],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert res.returncode == 0, res.stderr


@pytest.mark.parametrize("command", [("demo", "--small"), ("run", "RECORDING")])
def test_a_rerun_save_that_is_not_an_rrd_file_is_refused_before_the_run(cli, tmp_path, command):
    """A typo in --rerun-save costs nothing: exit 2 naming the option, nothing written."""
    args = [tmp_path / "rec.tum" if a == "RECORDING" else a for a in command]
    if command[0] == "run":
        (tmp_path / "rec.tum").write_text("0 0 0 0 0 0 0 1\n1 1 0 0 0 0 0 1\n")
    for bad in (tmp_path / "view.txt", tmp_path):
        out = tmp_path / "out"
        r = cli(*args, "--rerun-save", bad, "-o", out)
        assert r.exit_code == 2, r.output
        assert "--rerun-save" in r.output
        assert not out.exists() or not any(out.iterdir())
