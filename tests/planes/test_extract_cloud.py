"""Unorganised clouds: a simulated 360 deg room scan (density falling with range, like the PCL
room scans) - every surface extracted, and two scans registered with no initial guess."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from navkit.geometry import se3_from_rt, se3_inverse
from navkit.geometry.rotations import rotation_angle
from navkit.planes import MotionEstimate, estimate_motion, extract_planes_cloud
from navkit.planes.extract_cloud import cloud_scales
from navkit.planes.frame import PlaneObservation
from navkit.sim import Box, Scene, Wall, render_scan
from navkit.sim.scanners import RangeNoise, TiltingScanner

L, W, H = 10.0, 5.0, 3.0
SIGMA = 0.005  # range noise, metres
ROOM = Scene(
    [
        Wall(origin=(0, 0, 0), u=(L, 0, 0), v=(0, W, 0), name="floor"),
        Wall(origin=(0, 0, H), u=(L, 0, 0), v=(0, W, 0), name="ceiling"),
        Wall(origin=(0, 0, 0), u=(L, 0, 0), v=(0, 0, H), name="south"),
        Wall(origin=(0, W, 0), u=(L, 0, 0), v=(0, 0, H), name="north"),
        Wall(origin=(0, 0, 0), u=(0, W, 0), v=(0, 0, H), name="west"),
        Wall(origin=(L, 0, 0), u=(0, W, 0), v=(0, 0, H), name="east"),
        # furniture breaks the box's symmetry (a bare box looks the same turned by 180 deg)
        Box(center=(7.0, 1.0, 1.0), size=(1.2, 0.8, 2.0), name="cabinet"),
        Box(center=(2.0, 4.2, 1.5), size=(0.5, 0.5, 3.0), name="pillar"),
    ]
)
# (world normal, world offset) of the room's six surfaces: n . X = d
SURFACES = {
    "floor": ((0, 0, 1), 0.0),
    "ceiling": ((0, 0, 1), H),
    "south": ((0, 1, 0), 0.0),
    "north": ((0, 1, 0), W),
    "west": ((1, 0, 0), 0.0),
    "east": ((1, 0, 0), L),
}
# 0.5 deg x 1 deg over the full turn, +-85 deg elevation: ~123k points, half of them on the
# floor and ceiling within 2 m of the scanner (density falls with the square of the range)
SCANNER = TiltingScanner(
    azimuth_min_deg=-180,
    azimuth_max_deg=179.5,
    azimuth_step_deg=0.5,
    elevation_min_deg=-85,
    elevation_max_deg=85,
    elevation_step_deg=1.0,
)


def scanner_pose(x: float, y: float, yaw_deg: float) -> np.ndarray:
    return se3_from_rt(Rotation.from_euler("z", yaw_deg, degrees=True).as_matrix(), [x, y, 1.3])


@pytest.fixture(scope="module")
def room_pair():
    """Two scans 2.1 m and 40 deg apart: sensor-frame points and the true T_1_2."""
    poses = [scanner_pose(3.0, 2.0, 0.0), scanner_pose(5.0, 2.6, 40.0)]
    noise = RangeNoise(absolute_sigma=SIGMA)
    scans = [render_scan(ROOM, SCANNER, T, noise=noise, rng=k) for k, T in enumerate(poses)]
    pts = [s.scan.points("sensor").reshape(-1, 3) for s in scans]
    return pts, poses, se3_inverse(poses[0]) @ poses[1]


def test_every_room_surface_is_extracted(room_pair):
    """Floor, ceiling and the four walls, each as one plane with the true normal and distance.
    Tolerance: a TLS plane from N >= 1000 points with sigma = 5 mm spread over >= 2 m has a
    normal error ~ sigma sqrt(12) / (2 m sqrt(N)) = 0.03 deg and an offset error
    sigma / sqrt(N) = 0.2 mm; 0.2 deg / 5 mm leaves room for the band clipping the noise tails
    and for the voxel centroids at corners."""
    pts, poses, _ = room_pair
    for P, T in zip(pts, poses, strict=True):
        res = extract_planes_cloud(P)
        sc = cloud_scales(P)
        # the data-driven band follows the noise: 3 x the points' robust sigma across the
        # surface; range noise sigma projects to sigma cos(incidence) across a surface, and
        # most of a room's points are seen at incidence < 60 deg: 1.5 to 3 sigma (+ margin)
        assert 1.5 * SIGMA < sc.distance < 4 * SIGMA
        R, t = T[:3, :3], T[:3, 3]
        for name, (nw, dw) in SURFACES.items():
            n = R.T @ np.asarray(nw, float)  # world plane n . X = d seen from the sensor
            d = dw - np.asarray(nw, float) @ t
            found = [
                s
                for s in res.segments
                if abs(s.normal @ n) > np.cos(np.radians(0.2))
                and abs(s.rho - abs(d)) < 0.005
                and s.plane.count >= 1000
            ]
            assert found, f"{name} not extracted"
            assert all(s.rms < 2 * SIGMA for s in found)


def test_room_scans_registered_without_a_guess(room_pair):
    """40 deg and 2.1 m apart, no prior: global association + closed form. Tolerance from the
    plane errors above (0.03 deg, 0.2 mm per plane, >= 4 planes): 0.1 deg and 1 cm."""
    pts, _, truth = room_pair
    obs = [PlaneObservation(extract_planes_cloud(P), P) for P in pts]
    est = estimate_motion(*obs)
    assert isinstance(est, MotionEstimate) and est.case == 3
    E = se3_inverse(truth) @ est.T
    assert np.degrees(rotation_angle(E[:3, :3])) < 0.1
    assert np.linalg.norm(E[:3, 3]) < 0.01
