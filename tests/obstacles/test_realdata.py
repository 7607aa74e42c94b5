"""Real data: SemanticKITTI ground P/R/F1 (Patchwork++ protocol) and SqueezeSeg car recall."""

from __future__ import annotations

import pytest

from navkit.errors import InputError
from navkit.experiments.obstacles import car_recall
from navkit.io.pointcloud import read_kitti_bin, read_kitti_labels
from navkit.obstacles import Mounting, ObstacleSettings, detect_obstacles_in_grid
from navkit.obstacles.evaluate import ground_scores
from navkit.obstacles.grids import cloud_to_grid
from navkit.obstacles.rules import GROUND

pytestmark = pytest.mark.realdata


def test_semantickitti_ground_scores(data_path):
    folder = data_path("lidar/semantickitti-seq00")
    pts = read_kitti_bin(folder / "000000.bin")
    sem, _ = read_kitti_labels(folder / "000000.label", n_points=len(pts))
    grid = cloud_to_grid(pts)
    det = detect_obstacles_in_grid(grid, Mounting(1.73))
    labels = grid.per_point(det.vertex_labels)
    assert labels.shape == (len(pts),)
    s = ground_scores(labels == GROUND, sem)
    # measured on this frame: P 0.993, R 0.993, F1 0.993 (0.967 / 0.955 / 0.961 with the paper's
    # rules alone, ground_refine=False; Patchwork++ on the same frame: 0.986 / 0.995 / 0.991,
    # see docs/benchmarks/obstacles.md); the thresholds leave ~0.01 for changes of defaults,
    # not for regressions of the method
    assert s.precision >= 0.98
    assert s.recall >= 0.98
    assert s.f1 >= 0.985
    raw = detect_obstacles_in_grid(grid, Mounting(1.73), ObstacleSettings(ground_refine=False))
    s_raw = ground_scores(grid.per_point(raw.vertex_labels) == GROUND, sem)
    assert 0.95 <= s_raw.f1 < s.f1
    # about 260 obstacles' worth of structure: cars, walls, poles - at least dozens of obstacles
    assert len(det.obstacles) >= 30
    with pytest.raises(InputError):
        ground_scores(labels[:-1] == GROUND, sem)


def test_squeezeseg_cars_are_inside_obstacles(data_path):
    data_path("lidar/squeezeseg-kitti-raw")
    found, total, details = car_recall()
    # 10 labelled cars with >= 50 returns in the 4 frames. Every car lies inside the obstacles'
    # A1 rectangles (>= 95 % of its points; measured 100 % for all 10)
    assert total == 10
    assert all(d["inside_any_obstacle"] >= 0.95 for d in details), details
    # the obstacle owning most of a car's points holds >= 95 % of them in its own rectangle for
    # 8 of the 10 (the other two are split in two obstacles across a missing-return gap)
    assert found >= 8, [d for d in details if not d["found"]]
    # half of the owning rectangles are car-sized (<= 2x the car's own box); the others merge a
    # row of parked cars or a car and a hedge (measured median 6x)
    ratios = sorted(d["rect_area_over_car_box"] for d in details)
    assert sum(r <= 2.0 for r in ratios) >= 5
