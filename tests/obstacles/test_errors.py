"""Bad input gives a navkit error naming the field and what was expected, never a traceback."""

from __future__ import annotations

import numpy as np
import pytest

from navkit import jit
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
    from navkit.obstacles.evaluate import ground_scores

    path = tmp_path / "000000.label"
    np.arange(10, dtype=np.uint32).tofile(path)
    with pytest.raises(FormatError, match=r"000000\.label"):
        read_kitti_labels(path, n_points=12)
    with pytest.raises(InputError, match="semantic"):
        ground_scores(np.ones(12, bool), np.zeros(10, np.uint16))


def _floor_with_box() -> np.ndarray:
    az = np.radians(np.linspace(-60, 60, 61))
    el = np.radians(np.linspace(-40, -5, 21))
    d = 1.5 / np.sin(-el)
    P = np.stack(
        [np.outer(np.cos(az), d * np.cos(el)), np.outer(np.sin(az), d * np.cos(el))], axis=-1
    )
    P = np.concatenate([P, np.zeros((*P.shape[:2], 1))], axis=-1)
    P[25:35, 8:12, 2] = 0.8
    return P


@pytest.mark.parametrize("implementation", ["eager", "numpy"])
def test_coordinates_beyond_the_bound_are_refused_by_kernels_and_twins(implementation):
    """Finite coordinates beyond 1e9 m (here 1e30: their grid indices overflow) are refused
    before any kernel runs; NaN and inf stay no-returns."""
    P = _floor_with_box()
    settings = ObstacleSettings()
    with jit.use(implementation):
        with pytest.raises(
            InputError, match=r"field .points.: has a coordinate of magnitude .*e\+31 m"
        ):
            detect_obstacles_grid(P * 1e30, (0, 0, 1.5), settings)
        Q = P.copy()
        Q[3, 4] = [np.nan, np.inf, -np.inf]
        assert len(detect_obstacles_grid(Q, (0, 0, 1.5), settings).obstacles) == 1


@pytest.mark.parametrize("implementation", ["eager", "numpy"])
def test_ground_grid_beyond_the_cell_bound_is_refused_by_kernels_and_twins(
    implementation, monkeypatch
):
    """The ground-height grid's size is checked before it is allocated, with the same error from
    the kernel (which alone knows the reference points) and from the twin."""
    monkeypatch.setenv("NAVKIT_MAX_GRID_CELLS", "2")
    settings = ObstacleSettings(ground_cell_m=0.5)
    with jit.use(implementation), pytest.raises(InputError, match=r"ground_cell_m.*exceeds"):
        detect_obstacles_grid(_floor_with_box(), (0, 0, 1.5), settings)


def test_cloud_to_grid_sizes_are_checked_before_allocating():
    from navkit.obstacles.grids import cloud_to_grid

    cloud = np.random.default_rng(0).normal(size=(400, 3))
    for n in (10**9, 0, 1.5):
        with pytest.raises(InputError, match="n_columns"):
            cloud_to_grid(cloud, n_columns=n)  # type: ignore[arg-type]
    with pytest.raises(InputError, match="n_rings"):
        cloud_to_grid(cloud, n_rings=10**9, ring_method="elevation")
