"""Obstacles in a real KITTI lidar frame (paper 1), checked against SemanticKITTI's labels.

Reads one HDL-64E frame of the recorded data (NAVKIT_DATA), measures the sensor height from the
ground, runs the eight-stage detector and compares navkit's ground / obstacle classes with the
frame's semantic labels. With ``--out DIR`` it also writes the obstacle map figure.

    python examples/obstacles_kitti.py [--frame 000000] [--out out/example-obstacles]
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from navkit import datasets
from navkit.io.pointcloud import read_kitti_labels
from navkit.io.scans import read_scan_grid
from navkit.obstacles import Mounting, detect_obstacles_in_grid
from navkit.obstacles.mounting import estimate_sensor_height
from navkit.sensors.presets import get_preset


def main(argv: list[str] | None = None) -> dict[str, float]:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frame", default="000000")
    ap.add_argument("--out", type=Path, default=None, help="Folder for map.png (optional).")
    args = ap.parse_args(argv)

    folder = datasets.find("lidar/semantickitti-seq00")
    preset = get_preset("hdl64e-kitti")  # 64 beams stored ring after ring
    scan = read_scan_grid(
        folder / f"{args.frame}.bin", rings=preset.rings, ring_method=preset.ring_method
    )
    height = estimate_sensor_height(scan.grid.points)  # a plane fit to the ground around it
    det = detect_obstacles_in_grid(scan.grid, Mounting(height_m=height.height_m))
    labels = scan.grid.per_point(det.vertex_labels)

    semantic = read_kitti_labels(folder / f"{args.frame}.label")[0]
    road = np.isin(semantic, (40, 44, 48))  # road, parking, sidewalk
    solid = np.isin(semantic, (10, 50, 51, 70, 71, 80, 81))  # car, building, fence, plants, poles
    result = {
        "sensor_height_m": height.height_m,
        "n_obstacles": float(len(det.obstacles)),
        "road_as_ground": float((labels[road] == 0).mean()),
        "solid_as_obstacle": float((labels[solid] == -2).mean()),
    }
    print(
        f"{args.frame}: sensor {height.height_m:.3f} m above the ground (KITTI: 1.73 m), "
        f"{len(det.obstacles)} obstacles; SemanticKITTI road/sidewalk labelled ground: "
        f"{100 * result['road_as_ground']:.1f} %, cars/buildings/plants labelled obstacle: "
        f"{100 * result['solid_as_obstacle']:.1f} %"
    )
    if args.out is not None:
        from navkit.viz.obstacles import save_obstacle_map

        args.out.mkdir(parents=True, exist_ok=True)
        save_obstacle_map(args.out / "map.png", det, extent_m=40.0)
        print(f"figure -> {args.out / 'map.png'}")
    return result


if __name__ == "__main__":
    main()
