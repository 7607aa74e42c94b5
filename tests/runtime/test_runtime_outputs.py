"""The run's fast paths equal their references: the MarkerArray, the classified
PointCloud2 and the OccupancyGrid serialised with NumPy are byte for byte rosbags' serialisation of the same message, and the obstacle map's vectorised update
(:meth:`ObstacleMapper.update`) counts exactly what :meth:`ObstacleMapper.add_points` counts on
:func:`scan_points_2d`'s points (up to the rounding of points on a cell edge)."""

from __future__ import annotations

import numpy as np
import pytest

from navkit.runtime.messages import Polyline


@pytest.mark.parametrize("n_lines", [0, 1, 7])
def test_line_list_cdr_is_rosbags_serialisation(n_lines):
    pytest.importorskip("rosbags")
    from navkit.io.results_mcap import _builder, line_list_cdr, read_messages

    rng = np.random.default_rng(n_lines)
    lines = [
        Polyline(
            f"shape/A{k % 3}",
            k,
            rng.normal(size=(int(rng.integers(1, 40)), 3)),
            tuple(rng.random(4)),
            closed=bool(k % 2),
        )
        for k in range(n_lines)
    ]
    b = _builder()
    msgtype = "visualization_msgs/msg/MarkerArray"
    for stamp, frame in ((0, ""), (1_234_567_890_123, "velodyne"), (5, "a_frame")):
        want = bytes(b.ts.serialize_cdr(b.build("markers", stamp, frame, lines), msgtype))
        assert line_list_cdr(stamp, frame, lines) == want
    msg = b.ts.deserialize_cdr(line_list_cdr(7, "f", lines), msgtype)
    if n_lines:
        mk = msg.markers[1]
        n_seg = sum(
            len(ln.points) if ln.closed and len(ln.points) > 2 else len(ln.points) - 1
            for ln in lines
        )
        assert mk.type == 5 and len(mk.points) == 2 * n_seg == len(mk.colors)
    assert read_messages  # the module's reader decodes the same bytes (test_runtime_bags)


@pytest.mark.parametrize("n", [0, 1, 1000])
def test_classified_cloud_cdr_is_rosbags_serialisation(n):
    pytest.importorskip("rosbags")
    from navkit.io.results_mcap import _builder, classified_cloud_cdr

    rng = np.random.default_rng(n)
    P = rng.normal(size=(n, 3)) * 30
    P[::7] = np.nan  # no-return points travel as NaN
    cls = rng.integers(-4, 1, n).astype(np.int8)
    b = _builder()
    for stamp, frame in ((0, ""), (1_234_567_890_123, "velodyne"), (9, "abc")):
        msg = b.build("classified_cloud", stamp, frame, (P, cls))
        want = bytes(b.ts.serialize_cdr(msg, "sensor_msgs/msg/PointCloud2"))
        assert classified_cloud_cdr(stamp, frame, P, cls) == want


def test_vectorised_map_update_counts_like_add_points():
    from navkit.geometry import se3_from_rt
    from navkit.obstacles import Mounting, ObstacleSettings, detect_obstacles_in_grid
    from navkit.obstacles.grids import cloud_to_grid
    from navkit.obstacles.mapper import ObstacleMapper, ObstacleMapperSettings, scan_points_2d
    from navkit.sim import SpinningLidar, render_scan
    from tests.runtime.test_runtime_tf import _scene

    scene, lidar = _scene(), SpinningLidar(n_beams=16, n_columns=900)
    st = ObstacleMapperSettings(resolution=0.1, max_range=12.0)
    # the grid's cell edges off the boxes' faces: the two sum the transform in another order,
    # so a point within ~1e-15 m of a cell edge may fall either side (the simulated faces lie
    # exactly on a 0.1 m grid through the origin)
    lo, hi = np.array([-5.0123, -8.0123]), np.array([12.0, 8.0])
    fast, ref = ObstacleMapper(lo, hi, st), ObstacleMapper(lo, hi, st)
    for k in range(6):
        yaw = 0.2 * k
        c, s = np.cos(yaw), np.sin(yaw)
        T = se3_from_rt(np.array([[c, -s, 0], [s, c, 0], [0, 0, 1.0]]), [0.7 * k, 0.3 * k, 1.5])
        sim = render_scan(scene, lidar, T, max_range=30.0)
        P = sim.scan.points("sensor").transpose(1, 0, 2).reshape(-1, 3)
        P = P[np.all(np.isfinite(P), axis=1)]
        det = detect_obstacles_in_grid(cloud_to_grid(P), Mounting(1.5), ObstacleSettings())
        T_body = T @ np.linalg.inv(Mounting(1.5).T_body_sensor)
        planar = np.array([[c, -s, T[0, 3]], [s, c, T[1, 3]], [0, 0, 1.0]])
        for Tw in (T_body, planar) if k % 2 else (T_body,):
            fast.update(det, Tw)
            ref.add_points(*scan_points_2d(det, Tw, st.max_range))
    assert ref.hits.sum() > 0
    np.testing.assert_array_equal(fast.hits, ref.hits)
    np.testing.assert_array_equal(fast.seen, ref.seen)
    assert fast.n_scans == ref.n_scans
    for a, b in zip(fast.recent, ref.recent, strict=True):
        np.testing.assert_array_equal(a, b)


@pytest.mark.parametrize("shape", [(0, 0), (1, 1), (37, 53)])
def test_occupancy_grid_cdr_is_rosbags_serialisation(shape):
    pytest.importorskip("rosbags")
    from navkit.io.results_mcap import _builder, occupancy_grid_cdr

    rng = np.random.default_rng(shape[0])
    occ = rng.choice(np.array([-1, 0, 100], dtype=np.int8), size=shape)
    b = _builder()
    msgtype = "nav_msgs/msg/OccupancyGrid"
    for stamp, frame, res, origin in (
        (0, "", 0.1, (0.0, 0.0)),
        (1_234_567_890_123, "map", 0.05, (-100.25, 37.5)),
        (9, "odom", 1 / 3, np.array([1e-9, -7.0, 4.0])),  # a 3-vector: x, y kept
    ):
        want = bytes(b.ts.serialize_cdr(b.build("grid", stamp, frame, (occ, res, origin)), msgtype))
        assert occupancy_grid_cdr(stamp, frame, occ, res, origin) == want
    if occ.size:  # a strided view is copied as its cells
        view = occ[::-1, ::2]
        want = bytes(b.ts.serialize_cdr(b.build("grid", 5, "m", (view, 0.1, (1, 2))), msgtype))
        assert occupancy_grid_cdr(5, "m", view, 0.1, (1, 2)) == want


def test_segment_writer_writes_mcaps_unchunked_file(tmp_path):
    """A run's segment (``ResultsWriter(chunked=False)``, messages written as they are) is byte
    for byte the file of ``mcap``'s own ``Writer(use_chunking=False)`` given the same schemas,
    channels and messages: records, statistics, summary offsets and footer CRC."""
    pytest.importorskip("mcap")
    from mcap.writer import CompressionType, Writer

    from navkit.io.results_mcap import ResultsWriter, classified_cloud_cdr, read_messages

    rng = np.random.default_rng(3)
    P = rng.normal(size=(500, 3))
    cls = rng.integers(-4, 1, 500).astype(np.int8)
    cloud = "sensor_msgs/msg/PointCloud2"
    msgs = [
        ("/a", cloud, 5_000, classified_cloud_cdr(5_000, "v", P, cls)),
        ("/b", cloud, 3_000, b"\x00\x01\x00\x00" + bytes(range(40))),
        ("/a", cloud, 9_000, classified_cloud_cdr(9_000, "v", P[:7], cls[:7])),
        ("/c", "geometry_msgs/msg/PoseStamped", 4_000, b"\x00\x01\x00\x00" + bytes(60)),
    ]
    w = ResultsWriter(tmp_path / "ours.mcap", chunked=False)
    for topic, msgtype, t, raw in msgs:
        w.write_raw(topic, msgtype, t, raw, msgdef=b"def " + msgtype.encode())
        w.flush()
    w.close()
    with open(tmp_path / "ref.mcap", "wb") as fh:
        ref = Writer(fh, compression=CompressionType.NONE, use_chunking=False, chunk_size=1 << 20)
        ref.start(profile="ros2", library="navkit")
        schemas: dict[str, int] = {}
        channels: dict[str, int] = {}
        for topic, msgtype, t, raw in msgs:
            if topic not in channels:
                if msgtype not in schemas:
                    schemas[msgtype] = ref.register_schema(
                        msgtype, "ros2msg", b"def " + msgtype.encode()
                    )
                channels[topic] = ref.register_channel(topic, "cdr", schemas[msgtype])
            ref.add_message(channels[topic], log_time=t, data=bytes(raw), publish_time=t)
        ref.finish()
    assert (tmp_path / "ours.mcap").read_bytes() == (tmp_path / "ref.mcap").read_bytes()
    from mcap.reader import make_reader

    with open(tmp_path / "ours.mcap", "rb") as fh:
        reader = make_reader(fh)
        summary = reader.get_summary()
        assert summary is not None and summary.statistics.message_count == len(msgs)
        got = [
            (ch.topic, m.log_time, m.data)
            for _, ch, m in reader.iter_messages(log_time_order=False)
        ]
    assert got == [(t, s, bytes(raw)) for t, _, s, raw in msgs]
    cloud_msgs = list(read_messages(tmp_path / "ours.mcap", topics=["/a"]))
    np.testing.assert_array_equal(
        np.frombuffer(cloud_msgs[0].message.data, "<f4").reshape(-1, 4)[:, :3], P.astype(np.float32)
    )


def test_dumps_json_writes_non_finite_numbers_as_null():
    """The per-frame JSON (``navkit.runtime.files.dumps_json``): the standard library's text
    where every value is finite, ``null`` for NaN and infinities (in lists, values and nested
    arrays) and never inside a name."""
    import json

    from navkit.runtime.files import dumps_json

    doc = {"a": [1.5, 2, np.float64(0.1)], "b": np.arange(3.0), "NaN": "Infinity", "c": {"d": 1}}
    assert dumps_json(doc) == json.dumps(
        {"a": [1.5, 2, 0.1], "b": [0.0, 1.0, 2.0], "NaN": "Infinity", "c": {"d": 1}}
    )
    bad = {"x": [np.nan, 1.0, -np.inf], "y": np.inf, "z": np.array([np.nan, 2.0]), "NaN": "NaN"}
    assert json.loads(dumps_json(bad)) == {
        "x": [None, 1.0, None],
        "y": None,
        "z": [None, 2.0],
        "NaN": "NaN",
    }
