"""Work moved off the run's loop writes what the loop would have written: the segment written by
its thread (``navkit.runtime.segments.SegmentWriter``) is byte for byte the segment a
``ResultsWriter(chunked=False)`` writes in the caller's thread from the same outputs, whatever
the mix of outputs serialised in the loop and in the thread; a write error reaches the caller
as an ``InputError`` naming the segment; and ``obstacles.json`` formatted by the files' writer
from ``Obstacle.json_fields`` is ``Obstacle.to_dict``'s document."""

from __future__ import annotations

import json

import numpy as np
import pytest

from navkit.runtime.messages import Polyline


def _outputs(rng: np.random.Generator, n: int) -> list[tuple[str, str, int, str, object]]:
    """A frame-like mix: classified clouds and markers (serialised by the thread), poses and
    grids (serialised by the loop), stamps out of order."""
    out: list[tuple[str, str, int, str, object]] = []
    for k in range(n):
        stamp = int(rng.integers(0, 10**12))
        P = rng.normal(size=(int(rng.integers(0, 300)), 3)) * 20
        cls = rng.integers(-4, 1, len(P)).astype(np.int8)
        out.append(("/navkit/obstacles/points", "classified_cloud", stamp, "velodyne", (P, cls)))
        lines = [
            Polyline("shape/A1", j, rng.normal(size=(4, 3)), (0.9, 0.1, 0.1, 1.0))
            for j in range(int(rng.integers(0, 5)))
        ]
        out.append(("/navkit/obstacles/shapes", "markers", stamp, "velodyne", lines))
        T = np.eye(4)
        T[:3, 3] = rng.normal(size=3)
        out.append(("/navkit/pose", "pose", stamp + 1, "map", T))
        if k % 2:
            occ = rng.integers(-1, 2, size=(5, 7)).astype(np.int8)
            out.append(("/navkit/obstacle_map", "grid", stamp, "map", (occ, 0.2, np.zeros(2))))
    return out


def test_threaded_segment_is_the_synchronous_segment(tmp_path):
    pytest.importorskip("mcap")
    pytest.importorskip("rosbags")
    from navkit.io.results_mcap import ResultsWriter
    from navkit.runtime.segments import SegmentWriter

    outs = _outputs(np.random.default_rng(5), 40)
    ref = ResultsWriter(tmp_path / "ref.mcap", chunked=False)
    for o in outs:
        ref.write(*o)
    ref.close()
    # a small queue: the loop waits on the thread, and flushes come between outputs
    w = SegmentWriter(tmp_path / "ours.mcap", maxsize=3)
    for k, o in enumerate(outs):
        w.write(*o)
        if k % 5 == 4:
            w.flush()
    w.close()
    assert w.n_messages == len(outs)
    assert (tmp_path / "ours.mcap").read_bytes() == (tmp_path / "ref.mcap").read_bytes()


def test_segment_writer_errors_reach_the_caller(tmp_path):
    pytest.importorskip("mcap")
    from navkit.errors import InputError
    from navkit.runtime.segments import SegmentWriter

    w = SegmentWriter(tmp_path / "seg.mcap")
    with pytest.raises(InputError, match="unknown output kind"):
        w.write("/x", "no_such_kind", 0, "map", None)  # checked in the caller's thread
    # a cloud whose points are not (N, 3) fails in the thread: reported at the next call
    w.write("/c", "classified_cloud", 0, "v", (np.zeros((4, 2)), np.zeros(3, np.int8)))
    with pytest.raises(InputError, match=r"seg\.mcap"):
        w.close()


def test_obstacles_json_from_json_fields_is_to_dict(tmp_path):
    """The writer's ``"obstacles"`` kind on a real detection: the same document as
    ``to_dict`` encoded in the loop (NaN / infinite values written as ``null`` alike)."""
    from navkit.runtime.files import encode

    det = _detection()
    assert det.obstacles, "the wall is an obstacle"
    head = {"topic": "/c", "stamp_ns": 7, "frame": "body", "sensor": det.sensor_origin}
    want = encode("json", {**head, "obstacles": [ob.to_dict() for ob in det.obstacles]})
    fields = [ob.json_fields() for ob in det.obstacles]
    got = encode("obstacles", {**head, "obstacle_fields": fields})
    assert got == want
    assert json.loads(got)["obstacles"][0]["id"] == det.obstacles[0].id


def _detection():
    """A real detection: a wall 6 m away over 0.2 rad on level ground, seen from 1.5 m."""
    from navkit.obstacles import detect_obstacles
    from navkit.sensors import RangeScan

    rng = np.random.default_rng(0)
    az = np.radians(np.arange(-180.0, 180.0, 0.5))
    el = np.radians(np.linspace(-15.0, -1.0, 16))
    d = np.tile(1.5 / np.sin(-el), (az.size, 1))
    box = np.abs(az - 0.5) < 0.1
    d[box] = np.minimum(d[box], 6.0 / np.cos(el))
    d += rng.normal(0.0, 0.005, d.shape)
    return detect_obstacles(RangeScan(d, az, el, sensor_height=1.5, max_range=80.0))


@pytest.mark.parametrize("names", [None, ("A1", "A6"), ("A6", "MEC", "A7")])
def test_obstacle_lines_are_the_shapes_outlines(names):
    """The batched outlines of the shapes marker: each polyline is its shape's own
    ``outline(36)`` at the ground's height, bit for bit, in the obstacles' and shapes' order."""
    from navkit.runtime.capabilities import A7_COLOR, SHAPE_COLORS, obstacle_lines

    det = _detection()
    lines = obstacle_lines(det.obstacles, -1.5, names=names)
    want = []
    for ob in det.obstacles:
        for n, shp in ob.shapes.items():
            if names is None or n in names:
                want.append((ob.id, f"shape/{n}", shp.outline(36), SHAPE_COLORS[n]))
        if names is None or "A7" in names:
            want += [
                (ob.id, f"shape/A7:{n}", s.outline(36), A7_COLOR) for n, s in ob.guaranteed.items()
            ]
    assert len(lines) == len(want) > 0
    for ln, (oid, ns, xy, color) in zip(lines, want, strict=True):
        assert (ln.id, ln.ns, ln.color) == (oid, ns, color)
        np.testing.assert_array_equal(ln.points[:, :2], xy)
        assert np.all(ln.points[:, 2] == -1.5)
        # a whole Polyline record (built without its __init__): every field, closed
        assert vars(ln) == vars(Polyline(ns, oid, ln.points, color))
        assert ln.closed is True and type(ln) is Polyline


@pytest.mark.parametrize("span", [(0, 0), (-4, 0), (-4, 3), (-100, 100)])
def test_class_counts_are_the_points_per_class(span):
    """The frame record's per-class counts: every class present, ascending, with its number of
    points (``np.unique``'s), for the detector's few classes and for a wide span."""
    from navkit.runtime.capabilities import class_counts

    rng = np.random.default_rng(abs(span[0]))
    labels = rng.integers(span[0], span[1] + 1, 5000).astype(np.int8)
    labels[labels == span[0] + 1] = span[0]  # a class in the span that is absent
    values, counts = np.unique(labels, return_counts=True)
    got = class_counts(labels)
    assert list(got) == [str(v) for v in values.tolist()]
    assert list(got.values()) == counts.tolist()
    assert class_counts(labels[:0]) == {}


def test_the_files_writer_is_kept_between_users(tmp_path):
    """A released writer (drained: its files on disk) is the next user's; one whose process
    ended is not reused, and a second one released while one is kept is closed."""
    from navkit.runtime import files

    a = files.acquire_writer()
    a.submit_files([("json", tmp_path / "1" / "a.json", {"x": 1})])
    files.release_writer(a)
    assert json.loads((tmp_path / "1" / "a.json").read_text()) == {"x": 1}
    assert files.idle_writer_pid() == a._proc.pid
    b = files.acquire_writer()
    assert b is a and files.idle_writer_pid() is None
    c = files.acquire_writer()  # a second user at the same time: its own process
    assert c is not b
    files.release_writer(b)
    files.release_writer(c)  # one is kept already: c stops
    assert files.idle_writer_pid() == b._proc.pid and not c._proc.is_alive()
    b._proc.terminate()
    b._proc.join()
    d = files.acquire_writer()  # the kept one ended: a new one
    assert d is not b and d.usable()
    files.release_writer(d)
