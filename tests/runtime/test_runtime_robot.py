"""``navkit run`` as a robot node: on a ROS 2 bag recorded as a robot records it (``/scan`` in
``laser`` mounted 0.5 m ahead of ``base_link`` on ``/tf_static``, wheel odometry on ``/odom`` and
``/tf``), localized in a map of the log's first half, ``results.mcap`` carries the TF tree:

- every header frame links to ``map`` through the published transforms;
- ``base_link`` in ``map`` (``map -> odom`` from the fixes, AMCL's form, times the recording's
  ``odom -> base_link``) is within 0.2 m / 5 deg of the truth for >= 90 % of the scans: the map's
  own accuracy is about 0.1 m (``test_runtime_bags``: median error 0.06 m), the odometry between
  two fixes drifts by centimetres; a laser pose reported as the base's would be 0.5 m off;
- ``/navkit/localization/pose`` is ``base_link``'s pose with the match's covariance, equal to
  the TF chain's at the fix; ``/navkit/localization/sensor_pose`` is the laser's, 0.5 m ahead.
"""

from __future__ import annotations

import numpy as np
import pytest

from navkit.runtime.tf import TransformTree
from tests.runtime.bags import planar_pose, split_carmen, write_robot_bag

T_BASE_LASER = planar_pose(0.5, 0.0, 0.0, z=0.3)


def results_tf(path):
    """The TF tree of a results.mcap (every transform kept) and the header frame of every
    other message, by topic."""
    from navkit.io.results_mcap import read_messages

    tree = TransformTree(maxlen=1_000_000)
    frames: dict[str, set[str]] = {}
    for m in read_messages(path):
        if m.msgtype == "tf2_msgs/msg/TFMessage":
            for tr in m.message.transforms:
                t, q = tr.transform.translation, tr.transform.rotation
                from scipy.spatial.transform import Rotation

                T = np.eye(4)
                T[:3, :3] = Rotation.from_quat([q.x, q.y, q.z, q.w]).as_matrix()
                T[:3, 3] = t.x, t.y, t.z
                st = tr.header.stamp.sec * 1_000_000_000 + tr.header.stamp.nanosec
                tree.add(tr.header.frame_id, tr.child_frame_id, st, T, m.topic == "/tf_static")
        else:
            msg = m.message
            h = getattr(msg, "header", None)
            if h is None and getattr(msg, "markers", None):
                h = msg.markers[0].header
            if h is not None:
                frames.setdefault(m.topic, set()).add(h.frame_id)
    return tree, frames


def _err(T, Tt):
    pe = float(np.hypot(*(T[:2, 3] - Tt[:2, 3])))
    d = np.arctan2(T[1, 0], T[0, 0]) - np.arctan2(Tt[1, 0], Tt[0, 0])
    return pe, float(np.degrees(abs(np.angle(np.exp(1j * d)))))


@pytest.fixture(scope="module")
def robot_run(tmp_path_factory):
    pytest.importorskip("rosbags")
    pytest.importorskip("mcap")
    from navkit import datasets
    from navkit.errors import DataNotFoundError
    from navkit.runtime import run_recording

    try:
        log_gz = datasets.find("laser2d/freiburg-101-corrected.log.gz")
    except DataNotFoundError as exc:
        pytest.skip(f"recorded data absent: {exc}")
    d = tmp_path_factory.mktemp("robot")
    first, second = split_carmen(log_gz, d)
    run_recording(first, d / "map", {"run": {"capabilities": ["wall_map"]}})
    stamps, truth = write_robot_bag(second, d / "robot_bag", T_BASE_LASER)
    summary = run_recording(
        d / "robot_bag", d / "run", map_path=d / "map" / "wall_map" / "map.json"
    )
    return d, stamps, truth, summary


def test_every_frame_links_to_map_and_base_link_is_the_robot(robot_run):
    from navkit.io.results_mcap import read_messages

    d, stamps, truth, summary = robot_run
    assert "localization" in summary["capabilities"]
    tree, frames = results_tf(d / "run" / "results.mcap")
    used = set().union(*frames.values()) | set(tree.parent) | set(tree.parent.values())
    assert {"map", "odom", "base_link", "laser"} <= used
    for f in used:
        assert tree.can_transform("map", f), (f, tree.parent)
    assert tree.parent["odom"] == "map" and tree.parent["laser"] == "base_link"
    # base_link in map through the tree at every scan
    errs = np.array(
        [
            _err(tree.lookup("map", "base_link", int(s)), T)
            for s, T in zip(stamps, truth, strict=True)
        ]
    )
    good = (errs[:, 0] <= 0.2) & (errs[:, 1] <= 5.0)
    assert good.mean() >= 0.9, (good.mean(), np.median(errs, axis=0))
    # the laser pose taken as the base's would be 0.5 m off: the check can tell
    laser = np.array(
        [_err(tree.lookup("map", "laser", int(s)), T) for s, T in zip(stamps, truth, strict=True)]
    )
    assert np.median(laser[:, 0]) > 0.4

    base = {
        m.log_time_ns: m.message
        for m in read_messages(d / "run" / "results.mcap", ["/navkit/localization/pose"])
    }
    sensor = {
        m.log_time_ns: m.message
        for m in read_messages(d / "run" / "results.mcap", ["/navkit/localization/sensor_pose"])
    }
    assert base and set(base) == set(sensor)
    for st, msg in base.items():
        assert msg.header.frame_id == "map"
        p = msg.pose.pose.position
        T = tree.lookup("map", "base_link", st)
        np.testing.assert_allclose([p.x, p.y], T[:2, 3], atol=1e-6)
        s = sensor[st].pose.position
        assert abs(np.hypot(s.x - p.x, s.y - p.y) - 0.5) < 1e-6
        C = np.asarray(msg.pose.covariance).reshape(6, 6)
        np.testing.assert_allclose(C, C.T, atol=1e-12)
        sub = C[np.ix_([0, 1, 5], [0, 1, 5])]
        assert np.linalg.eigvalsh(sub).min() > 0
        # 3-sigma of the reported covariance is within a map cell's reach of a metre: the
        # match's spread, not a placeholder
        assert np.sqrt(C[0, 0] + C[1, 1]) < 1.0
    # the reference is scored at the laser (carried through TF), as map locate scores it
    loc = summary["capabilities"]["localization"]
    assert loc["position_error_m_median"] < 0.2
