"""ROS bags: write a tiny ROS1 bag and ROS2 bag with rosbags' writers, read them back."""

from __future__ import annotations

import numpy as np
import pytest

from navkit.errors import FormatError

rosbags = pytest.importorskip("rosbags", reason="rosbags (extra 'rosbag') not installed")

from rosbags.typesys import Stores, get_typestore  # noqa: E402

from navkit.io.rosbag import iter_images, iter_pointclouds, list_topics  # noqa: E402


def _messages(ts, rng):
    """An organised 4 x 5 cloud (x y z intensity rgb, padded, NaN points) and two images."""
    T = ts.types
    Header = T["std_msgs/msg/Header"]
    Time = T["builtin_interfaces/msg/Time"]
    PointField = T["sensor_msgs/msg/PointField"]
    h, w = 4, 5
    n = h * w
    xyz = rng.normal(size=(n, 3)).astype(np.float32)
    xyz[7] = np.nan
    inten = rng.random(n).astype(np.float32)
    colors = rng.integers(0, 256, (n, 3)).astype(np.uint8)
    packed = (
        (colors[:, 0].astype(np.uint32) << 16)
        | (colors[:, 1].astype(np.uint32) << 8)
        | colors[:, 2]
    )
    # point_step 32 with padding after x y z (like PCL's PointXYZ + data[4]) and row padding
    rec = np.zeros(
        n,
        dtype={
            "names": ["x", "y", "z", "intensity", "rgb"],
            "formats": ["<f4"] * 4 + ["<u4"],
            "offsets": [0, 4, 8, 16, 20],
            "itemsize": 32,
        },
    )
    rec["x"], rec["y"], rec["z"], rec["intensity"], rec["rgb"] = *xyz.T, inten, packed
    row_step = w * 32 + 8
    data = np.zeros((h, row_step), np.uint8)
    data[:, : w * 32] = rec.view(np.uint8).reshape(h, w * 32)
    fields = [
        PointField(name="x", offset=0, datatype=7, count=1),
        PointField(name="y", offset=4, datatype=7, count=1),
        PointField(name="z", offset=8, datatype=7, count=1),
        PointField(name="intensity", offset=16, datatype=7, count=1),
        PointField(name="rgb", offset=20, datatype=7, count=1),
    ]

    def header(sec, frame):
        extra = {"seq": 0} if "seq" in Header.__dataclass_fields__ else {}  # ROS1 only
        return Header(stamp=Time(sec=sec, nanosec=500_000_000), frame_id=frame, **extra)

    cloud = T["sensor_msgs/msg/PointCloud2"](
        header=header(10, "velodyne"),
        height=h,
        width=w,
        fields=fields,
        is_bigendian=False,
        point_step=32,
        row_step=row_step,
        data=data.ravel(),
        is_dense=False,
    )
    rgb = rng.integers(0, 256, (3, 4, 3)).astype(np.uint8)
    Image = T["sensor_msgs/msg/Image"]
    bgr_msg = Image(
        header=header(11, "cam"),
        height=3,
        width=4,
        encoding="bgr8",
        is_bigendian=0,
        step=4 * 3,
        data=np.ascontiguousarray(rgb[:, :, ::-1]).ravel(),
    )
    depth = rng.integers(0, 5000, (3, 4)).astype(np.uint16)
    depth_msg = Image(
        header=header(12, "cam"),
        height=3,
        width=4,
        encoding="16UC1",
        is_bigendian=0,
        step=4 * 2 + 4,
        data=np.pad(depth.view(np.uint8).reshape(3, 8), ((0, 0), (0, 4))).ravel(),
    )
    truth = {"xyz": xyz, "intensity": inten, "colors": colors, "rgb": rgb, "depth": depth}
    return cloud, bgr_msg, depth_msg, truth


def _check(path, truth):
    topics = list_topics(path)
    assert topics["/points"] == ("sensor_msgs/msg/PointCloud2", 1)
    assert topics["/camera/color"][1] == 1
    (msg,) = list(iter_pointclouds(path))
    cloud = msg.data
    assert msg.topic == "/points" and msg.frame_id == "velodyne" and msg.timestamp == 10.5
    assert cloud.is_organized and cloud.grid().shape == (4, 5, 3)
    np.testing.assert_array_equal(cloud.points, truth["xyz"].astype(np.float64))
    np.testing.assert_array_equal(cloud.fields["intensity"], truth["intensity"])
    np.testing.assert_array_equal(cloud.colors, truth["colors"])
    imgs = {m.topic: m for m in iter_images(path)}
    np.testing.assert_array_equal(imgs["/camera/color"].data, truth["rgb"])
    np.testing.assert_array_equal(imgs["/camera/depth"].data, truth["depth"])
    assert imgs["/camera/depth"].encoding == "16UC1" and imgs["/camera/depth"].timestamp == 12.5
    (only,) = list(iter_images(path, topics="/camera/depth"))
    assert only.topic == "/camera/depth"
    with pytest.raises(FormatError, match=r"no sensor_msgs/msg/Image topic.*/nope"):
        list(iter_images(path, topics=["/nope"]))


def test_ros1_bag(tmp_path, rng):
    from rosbags.rosbag1 import Writer

    ts = get_typestore(Stores.ROS1_NOETIC)
    cloud, bgr, depth, truth = _messages(ts, rng)
    path = tmp_path / "tiny.bag"
    with Writer(path) as writer:
        for topic, msg in (("/points", cloud), ("/camera/color", bgr), ("/camera/depth", depth)):
            conn = writer.add_connection(topic, msg.__msgtype__, typestore=ts)
            writer.write(conn, 1_000_000_000, ts.serialize_ros1(msg, msg.__msgtype__))
    _check(path, truth)


def test_ros2_bag(tmp_path, rng):
    from rosbags.rosbag2 import Writer

    ts = get_typestore(Stores.ROS2_HUMBLE)
    cloud, bgr, depth, truth = _messages(ts, rng)
    path = tmp_path / "tiny_ros2"
    with Writer(path, version=9) as writer:
        for topic, msg in (("/points", cloud), ("/camera/color", bgr), ("/camera/depth", depth)):
            conn = writer.add_connection(topic, msg.__msgtype__, typestore=ts)
            writer.write(conn, 1_000_000_000, ts.serialize_cdr(msg, msg.__msgtype__))
    _check(path, truth)


def test_not_a_bag(tmp_path):
    p = tmp_path / "junk.bag"
    p.write_bytes(b"nothing here")
    with pytest.raises(FormatError, match=r"junk\.bag.*cannot open"):
        list_topics(p)


# --------------------------------------------------------------------------- bags as robots leave them
def _all(path):
    """``(topic, bag time, stamp ns)`` of every message of a bag, in the order it is read."""
    from navkit.io.rosbag import iter_raw_messages, stamp_ns

    return [(t, ns, stamp_ns(m, ns)) for t, _typ, ns, m in iter_raw_messages(path)]


def test_ccny_2010_bag_is_read_by_scanning(data_path, caplog):
    """The real 2010 ROS 1 bag whose index rosbags rejects: all 278 LaserScans over 27.6 s
    (its SOURCE.txt), with one warning saying how many messages were recovered."""
    import logging

    from navkit.io.rosbag import bag_info, iter_raw_messages, laserscan_from_msg

    bag = data_path("bags/ccny-laser-2010.bag")
    caplog.set_level(logging.WARNING, logger="navkit.io.rosbag")
    info = bag_info(bag)
    assert info.topics == {"/scan": ("sensor_msgs/msg/LaserScan", 278)}
    assert abs((info.end_ns - info.start_ns) * 1e-9 - 27.6) < 0.05
    scans = [laserscan_from_msg(m) for _t, _typ, _ns, m in iter_raw_messages(bag)]
    assert len(scans) == 278
    assert all(np.isfinite(r).sum() > len(r) // 2 for r, _b, _rmax in scans)
    warnings = [r.getMessage() for r in caplog.records if r.levelno == logging.WARNING]
    assert len(warnings) == 1 and "278 messages recovered" in warnings[0], warnings
    stamps = [s for _t, _ns, s in _all(bag)]
    assert stamps == sorted(stamps)


@pytest.fixture(scope="module")
def whole_bags(tmp_path_factory):
    """CARMEN scans + odometry as a ROS 1 bag and a ROS 2 (mcap storage) bag."""
    from navkit import datasets
    from navkit.errors import DataNotFoundError
    from tests.runtime.bags import write_carmen_bag

    try:
        log_gz = datasets.find("laser2d/freiburg-101-corrected.log.gz")
    except DataNotFoundError as exc:
        pytest.skip(f"recorded data absent: {exc}")
    d = tmp_path_factory.mktemp("cut")
    write_carmen_bag(log_gz, d / "whole.bag", ros1=True, every=4)
    write_carmen_bag(log_gz, d / "whole_ros2", ros1=False, every=4)
    return d


def _cut(src, dest, fraction):
    data = src.read_bytes()
    dest.write_bytes(data[: int(len(data) * fraction)])
    return len(data)


@pytest.mark.realdata
@pytest.mark.parametrize("ros1", [True, False])
def test_bags_cut_short_are_read_up_to_the_last_whole_message(whole_bags, tmp_path, ros1):
    """A bag cut at 30, 60 and 90 % of its bytes (as a crash leaves it): the messages read are
    exactly the first ones of the whole bag, and all of them whose bytes lie before the cut
    but for the records in flight."""
    from navkit.io.rosbag import bag_info

    d = whole_bags
    if ros1:
        src = d / "whole.bag"
    else:
        (src,) = sorted((d / "whole_ros2").glob("*.mcap"))
    full = _all(d / "whole.bag" if ros1 else d / "whole_ros2")
    raw_sizes = []
    counts = []
    for fraction in (0.3, 0.6, 0.9):
        if ros1:
            cut = tmp_path / f"cut{fraction}.bag"
        else:
            folder = tmp_path / f"cut{fraction}"
            folder.mkdir()
            (folder / "metadata.yaml").write_bytes(
                (d / "whole_ros2" / "metadata.yaml").read_bytes()
            )
            cut = folder
        size = _cut(src, cut if ros1 else cut / src.name, fraction)
        got = _all(cut)
        assert got == full[: len(got)]
        info = bag_info(cut)
        assert info.n_messages == len(got)
        counts.append(len(got))
        if not raw_sizes:  # the serialised sizes, read from the whole bag by rosbags itself
            from rosbags.highlevel import AnyReader

            whole = d / "whole.bag" if ros1 else d / "whole_ros2"
            with AnyReader([whole], default_typestore=get_typestore(Stores.LATEST)) as r:
                raw_sizes = [len(raw) for _c, _t, raw in r.messages()]
        # every message ending before the cut is read: the messages are at most `per` bytes
        # apart with their record headers (< 128 bytes), after the file's header region
        # (ROS 1: 4 KiB bag header; MCAP: header, schemas, channels)
        per = 2 * (max(raw_sizes) + 128)  # one scan and one odometry record per scan time
        assert len(got) >= 2 * ((int(size * fraction) - 8192) // per) - 2, (fraction, len(got))
    assert counts == sorted(counts) and counts[-1] < len(full)
