"""The Rerun logger draws every output in its header frame and chains the frames through the TF
tree the run publishes, as Foxglove and RViz do with ``results.mcap``: read back from the
``.rrd``, each entity's ``CoordinateFrame`` is its message's frame, each TF edge is a named-frame
``Transform3D`` (parent, child, the transform), and composing the edges gives the laser in ``map``
that the inputs compose to. Also: what Rerun's own MCAP importer makes of ``results.mcap``
(``rerun results.mcap``, documented in docs/runtime.md)."""

from __future__ import annotations

import numpy as np
import pytest

from navkit.runtime.messages import Message, Output, Polyline, ScanData
from tests.runtime.bags import planar_pose

rr = pytest.importorskip("rerun")
chunk = pytest.importorskip("rerun.chunk")
if not hasattr(rr, "CoordinateFrame") or not hasattr(chunk, "RrdReader"):
    pytest.skip("rerun-sdk without named transform frames", allow_module_level=True)


def _rows(path):
    """Every logged row of an .rrd: (entity, static, {component: value})."""
    out = []
    for c in chunk.RrdReader(path).stream():
        d = c.to_record_batch().to_pydict()
        comps = {k: v for k, v in d.items() if ":" in k}
        for i in range(c.num_rows):
            out.append((c.entity_path, c.is_static, {k: v[i] for k, v in comps.items()}))
    return out


def _T(row):
    T = np.eye(4)
    T[:3, 3] = row["Transform3D:translation"][0]
    if row.get("Transform3D:mat3x3") is not None:
        # Rerun stores 3x3 matrices column-major
        T[:3, :3] = np.asarray(row["Transform3D:mat3x3"][0], dtype=np.float64).reshape(3, 3).T
    return T


def test_outputs_in_their_frames_chained_by_tf(tmp_path):
    from navkit.viz.rerun_logger import RerunLogger

    T_map_odom = planar_pose(1.0, -2.0, 0.3)
    T_odom_base = planar_pose(4.0, 1.5, -0.7, z=0.3)
    T_base_laser = planar_pose(0.5, 0.0, 0.0, z=0.3)
    st = 1_000_000_000
    rrd = tmp_path / "run.rrd"
    lg = RerunLogger(save=rrd)
    lg.set_time(st)
    lg.log_output(Output("/tf_static", "tf", st, "base_link", [("laser", T_base_laser)]))
    lg.log_output(Output("/tf", "tf", st, "odom", [("base_link", T_odom_base)]))
    lg.log_output(Output("/tf", "tf", st, "map", [("odom", T_map_odom)]))
    bearings = np.linspace(-1.5, 1.5, 31)
    ranges = np.full(31, 3.0)
    ranges[4] = np.nan  # no return: not drawn
    lg.log_message(Message("/scan", "scan", st, "laser", ScanData(ranges, bearings, 30.0)))
    lg.log_output(
        Output(
            "/navkit/obstacles/points",
            "classified_cloud",
            st,
            "base_link",
            (np.ones((5, 3)), np.zeros(5, np.int8)),
        )
    )
    wall = Polyline("walls", 0, np.array([[0.0, 0, 0], [5, 0, 0]]), (0, 0, 1, 1), closed=False)
    lg.log_output(Output("/navkit/walls", "markers", st, "map", [wall]))
    T_fix = planar_pose(5.0, 0.2, 0.1)
    lg.log_output(Output("/navkit/localization/pose", "pose", st, "map", T_fix))
    lg.close()

    rows = _rows(rrd)
    frames = {e: r["CoordinateFrame:frame"][0] for e, _, r in rows if "CoordinateFrame:frame" in r}
    assert frames["/world/scan"] == "laser"
    assert frames["/world/obstacles/points"] == "base_link"
    assert frames["/world/walls"] == "map"
    for f in ("map", "odom", "base_link", "laser"):  # each TF frame drawn as labelled axes
        assert frames[f"/world/tf/{f}"] == f
    scan = next(r for e, _, r in rows if e == "/world/scan" and "Points3D:positions" in r)
    assert len(scan["Points3D:positions"]) == 30

    edges, static = {}, {}
    for _e, s, r in rows:
        if r.get("Transform3D:child_frame"):
            child = r["Transform3D:child_frame"][0]
            edges[child] = (r["Transform3D:parent_frame"][0], _T(r))
            static[child] = s
    assert {c: p for c, (p, _) in edges.items()} == {
        "laser": "base_link",
        "base_link": "odom",
        "odom": "map",
    }
    assert static == {"laser": True, "base_link": False, "odom": False}

    def in_map(frame):
        T = np.eye(4)
        while frame != "map":
            parent, T_pc = edges[frame]
            T, frame = T_pc @ T, parent
        return T

    # float32 storage: 1e-5 m over a few metres
    np.testing.assert_allclose(in_map("laser"), T_map_odom @ T_odom_base @ T_base_laser, atol=1e-5)
    fix = next(
        r for e, _, r in rows if e == "/world/localization/pose" and "Transform3D:translation" in r
    )
    assert fix["Transform3D:parent_frame"][0] == "map"
    np.testing.assert_allclose(_T(fix), T_fix, atol=1e-6)


def test_rerun_reads_results_mcap(tmp_path):
    """Rerun's MCAP importer turns results.mcap's TF into named-frame transforms and its clouds,
    grids and sensor poses into points, grid maps and poses in their header frames; markers,
    paths and poses with covariance stay raw messages (not drawn by ``rerun results.mcap``)."""
    pytest.importorskip("rosbags")
    pytest.importorskip("mcap")
    if not hasattr(chunk, "McapReader"):
        pytest.skip("rerun-sdk without the MCAP reader")
    from navkit.io.results_mcap import ResultsWriter

    p = tmp_path / "results.mcap"
    T = planar_pose(1.0, 2.0, 0.4)
    pts = np.random.default_rng(0).normal(size=(40, 3))
    w = ResultsWriter(p)
    w.write("/tf_static", "tf", 10, "map", [("odom", np.eye(4))])
    w.write("/tf", "tf", 10, "odom", [("base_link", T)])
    w.write(
        "/navkit/obstacles/points",
        "classified_cloud",
        10,
        "base_link",
        (pts, np.zeros(40, np.int8)),
    )
    w.write(
        "/navkit/obstacle_map", "grid", 10, "map", (np.zeros((4, 5), np.int8), 0.1, np.zeros(3))
    )
    w.write("/navkit/localization/sensor_pose", "pose", 10, "map", T)
    w.write(
        "/navkit/walls",
        "markers",
        10,
        "map",
        [Polyline("walls", 0, np.array([[0.0, 0, 0], [1, 0, 0]]), (1, 0, 0, 1), False)],
    )
    w.write("/navkit/path", "path", 10, "map", np.array([[0.0, 0, 0], [1, 1, 0]]))
    w.write("/navkit/localization/pose", "pose_cov", 10, "map", (T, np.eye(6) * 0.01))
    w.close()

    comps: dict[str, dict] = {}
    for c in chunk.McapReader(p).stream():
        d = c.to_record_batch().to_pydict()
        comps.setdefault(c.entity_path, {}).update({k: v[0] for k, v in d.items() if ":" in k})
    tf = comps["/tf"]
    assert (tf["Transform3D:parent_frame"][0], tf["Transform3D:child_frame"][0]) == (
        "odom",
        "base_link",
    )
    np.testing.assert_allclose(tf["Transform3D:translation"][0], T[:3, 3])
    assert comps["/tf_static"]["Transform3D:child_frame"][0] == "odom"
    cloud = comps["/navkit/obstacles/points"]
    assert cloud["CoordinateFrame:frame"][0] == "base_link"
    np.testing.assert_allclose(cloud["Points3D:positions"], pts, atol=1e-6)  # float32
    assert comps["/navkit/obstacle_map"]["CoordinateFrame:frame"][0] == "map"
    assert "GridMap:data" in comps["/navkit/obstacle_map"]
    pose = comps["/navkit/localization/sensor_pose"]
    assert pose["CoordinateFrame:frame"][0] == "map"
    np.testing.assert_allclose(pose["InstancePoses3D:translations"][0], T[:3, 3])
    drawn = ("Points3D", "LineStrips3D", "Transform3D", "InstancePoses3D", "GridMap", "Arrows3D")
    for topic, msgtype in (
        ("/navkit/walls", "visualization_msgs.msg.MarkerArray"),
        ("/navkit/path", "nav_msgs.msg.Path"),
        ("/navkit/localization/pose", "geometry_msgs.msg.PoseWithCovarianceStamped"),
    ):
        assert f"{msgtype}:message" in comps[topic]
        assert not any(k.startswith(drawn) for k in comps[topic]), comps[topic].keys()
