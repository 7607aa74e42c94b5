"""The CARMEN log reader on the real logs and on broken ones."""

from __future__ import annotations

import gzip

import numpy as np
import pytest

from navkit.errors import DataNotFoundError, FormatError
from navkit.io.carmen import read_carmen


def _flaser(n=5, r=1.0, pose=(1.0, 2.0, 0.5), t=10.0):
    ranges = " ".join([str(r)] * n)
    return f"FLASER {n} {ranges} {pose[0]} {pose[1]} {pose[2]} 0.9 1.9 0.4 {t} host {t + 0.01}\n"


def test_reads_flaser_and_odom(tmp_path):
    p = tmp_path / "tiny.log"
    p.write_text(
        "# comment\nPARAM x 1\nODOM 1 2 0.1 0.3 0.01 0 5.0 host 5.01\n"
        + _flaser()
        + "NEFF 12\n"
        + _flaser(t=11.0)
    )
    lg = read_carmen(p)
    assert len(lg) == 2 and lg.ranges.shape == (2, 5)
    np.testing.assert_allclose(lg.poses[0], [1.0, 2.0, 0.5])
    np.testing.assert_allclose(lg.odom_poses[0], [0.9, 1.9, 0.4])
    np.testing.assert_allclose(lg.timestamps, [10.01, 11.01])
    np.testing.assert_allclose(lg.bearings, np.linspace(-np.pi / 2, np.pi / 2, 5))
    np.testing.assert_allclose(lg.odom_xytheta, [[1, 2, 0.1]])
    assert lg.skipped == {"PARAM": 1, "NEFF": 1}
    # points: r = 1 along the bearings
    np.testing.assert_allclose(np.linalg.norm(lg.points(0), axis=1), 1.0)


def test_gzip_is_detected_by_content(tmp_path):
    p = tmp_path / "tiny.log.gz"
    with gzip.open(p, "wt") as fh:
        fh.write(_flaser(n=3))
    assert read_carmen(p).ranges.shape == (1, 3)


@pytest.mark.parametrize(
    "text, match",
    [
        ("ODOM 0 0 0 0 0 0 1 h 1\n" + _flaser()[:40] + "\n", "line 2"),  # truncated FLASER line
        (_flaser() + "FLASER x 1 2\n", "line 2: beam count"),
        (_flaser() + _flaser().replace("1.0 1.0", "1.0 abc", 1), "line 2"),
        (_flaser(n=5) + _flaser(n=4), "4 beams after 5"),
        ("ODOM 0 0 0 0 0 0 1 h 1\n", "no FLASER"),
        ("ODOM 0 0 zero 0 0 0 1 h 1\n" + _flaser(), "line 1"),
    ],
)
def test_broken_logs_raise_format_errors_with_line_numbers(tmp_path, text, match):
    p = tmp_path / "broken.log"
    p.write_text(text)
    with pytest.raises(FormatError, match=match) as exc:
        read_carmen(p)
    assert str(p) in str(exc.value)


def test_truncated_gzip_and_missing_file(tmp_path):
    p = tmp_path / "cut.log.gz"
    data = gzip.compress((_flaser() * 200).encode())
    p.write_bytes(data[: len(data) // 2])
    with pytest.raises(FormatError, match="cannot be read"):
        read_carmen(p)
    with pytest.raises(DataNotFoundError):
        read_carmen(tmp_path / "absent.log")


@pytest.mark.realdata
def test_real_intel_log(data_path):
    lg = read_carmen(data_path("laser2d/intel-corrected.log.gz"))
    assert lg.ranges.shape == (910, 180)
    assert len(lg.odom_t) == 14541
    # the corrected poses are a continuous path: consecutive scans < 1.5 m apart
    step = np.linalg.norm(np.diff(lg.poses[:, :2], axis=0), axis=1)
    assert step.max() < 1.5
    # valid ranges are metres of an office (< 82 m max reading)
    assert np.nanmax(lg.ranges) < 82.0 and np.nanmin(lg.ranges) > 0
