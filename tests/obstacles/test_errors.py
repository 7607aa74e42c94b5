"""Bad input gives a navkit error naming the field and what was expected, never a traceback."""

from __future__ import annotations

import numpy as np
import pytest

from navkit.errors import ConfigError, InputError
from navkit.obstacles import ObstacleSettings, detect_obstacles, detect_obstacles_grid
from navkit.sensors import RangeScan


def test_empty_and_all_nan_scans():
    with pytest.raises(InputError, match="ranges"):
        RangeScan(np.zeros((0, 5)), np.zeros(0), np.linspace(-0.5, 0, 5))
    scan = RangeScan(np.full((4, 5), np.nan), np.linspace(-1, 1, 4), np.linspace(-0.5, 0, 5))
    with pytest.raises(InputError, match="no valid point"):
        detect_obstacles(scan)


def test_wrong_shapes_and_dtypes():
    with pytest.raises(InputError, match=r"\(n_az, n_el, 3\)"):
        detect_obstacles_grid(np.zeros((10, 3)))
    with pytest.raises(InputError, match="2 x 2"):
        detect_obstacles_grid(np.zeros((1, 5, 3)))
    with pytest.raises(InputError, match="numeric"):
        detect_obstacles_grid(np.full((3, 3, 3), "x"))
    with pytest.raises(InputError, match="RangeScan"):
        detect_obstacles(np.zeros((3, 3)))  # type: ignore[arg-type]


def test_bad_settings():
    with pytest.raises(ConfigError, match="c0_deg"):
        ObstacleSettings(c0_deg=95)
    with pytest.raises(ConfigError, match="shapes"):
        ObstacleSettings(shapes=("A1", "A9"))
    with pytest.raises(ConfigError, match="unknown keys"):
        ObstacleSettings.from_dict({"c0": 3})


def test_labels_of_the_wrong_length(tmp_path):
    from navkit.errors import FormatError
    from navkit.io.pointcloud import read_kitti_labels
    from navkit.obstacles import ground_scores

    path = tmp_path / "000000.label"
    np.arange(10, dtype=np.uint32).tofile(path)
    with pytest.raises(FormatError, match=r"000000\.label"):
        read_kitti_labels(path, n_points=12)
    with pytest.raises(InputError, match="semantic"):
        ground_scores(np.ones(12, bool), np.zeros(10, np.uint16))
