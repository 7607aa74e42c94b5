"""Planes and plane odometry (paper 2) on two RGB-D frames of the recorded data (slambook ch. 5).

Extracts the planes of two frames (default 2 and 3) and estimates the camera motion between them
from the planes and their texture, then compares it with the data set's reference poses
(``pose.txt``). A pair whose motion the planes cannot fix is reported as such (frames 1 -> 2:
the texture match is not confirmed by the rest of the scene), never as a pose.

    python examples/planes_slambook.py [--frames 2 3]
"""

from __future__ import annotations

import argparse

import numpy as np

from navkit import datasets
from navkit.geometry import se3_from_xyz_quat, se3_inverse
from navkit.geometry.rotations import rotation_angle
from navkit.io.rgbd import open_rgbd_sequence
from navkit.planes import estimate_motion, observe_rgbd

CAMERA = {"fx": 518.0, "fy": 519.0, "cx": 325.5, "cy": 253.5, "depth_scale": 1000.0}
"""The slambook's Kinect intrinsics (pixels) and depth units per metre."""


def main(argv: list[str] | None = None) -> dict[str, float]:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, nargs=2, default=(2, 3), help="1-based frame numbers")
    args = ap.parse_args(argv)
    a, b = args.frames[0] - 1, args.frames[1] - 1

    folder = datasets.find("rgbd/slambook-ch5")
    seq = open_rgbd_sequence(folder, CAMERA)
    o1, o2 = observe_rgbd(seq.frame(a)), observe_rgbd(seq.frame(b))
    est = estimate_motion(o1, o2)
    print(
        f"frame {a + 1}: {len(o1.extraction.planes)} planes, "
        f"frame {b + 1}: {len(o2.extraction.planes)} planes"
    )
    if not est.ok:
        print(f"no motion: {est.reason}")
        return {"ok": 0.0}
    tab = np.loadtxt(folder / "pose.txt", ndmin=2)  # tx ty tz qx qy qz qw, T_world_camera
    ref = se3_from_xyz_quat(tab[:, :3], tab[:, 3:])
    T_ref = se3_inverse(ref[a]) @ ref[b]
    dt = float(np.linalg.norm(est.T[:3, 3] - T_ref[:3, 3]))
    dr = float(np.degrees(rotation_angle(est.T[:3, :3].T @ T_ref[:3, :3])))
    print(
        f"motion {np.linalg.norm(est.T[:3, 3]):.3f} m, "
        f"{np.degrees(rotation_angle(est.T[:3, :3])):.1f} deg ({est.case}); against pose.txt: "
        f"{100 * dt:.1f} cm, {dr:.2f} deg"
    )
    return {"ok": 1.0, "translation_error_m": dt, "rotation_error_deg": dr}


if __name__ == "__main__":
    main()
