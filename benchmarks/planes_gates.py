"""Do the dense step's gates transfer between sequences? Calibrate on one, check on the other.

The protocol of :mod:`navkit.planes.gates_calibration` on both shared sequences
(``rgbd/7scenes-tsdf``, KinectFusion reference; ``rgbd/tum-fr3-structure-notexture-far``, motion
capture): pairs 1 and 10 frames apart from frames 10, 18, ..., 82, each aligned from the
reference motion spoiled by 0-80 cm / 0-20 deg; gates derived from one sequence's right results
are applied to the other's, both ways, and the default
:class:`~navkit.planes.odometry.DenseGates` to both.

Run: ``python -m benchmarks.planes_gates`` (prints the tables; about 10 s).
"""

from __future__ import annotations

import numpy as np

SEQUENCES = {"7-Scenes": "rgbd/7scenes-tsdf", "TUM": "rgbd/tum-fr3-structure-notexture-far"}


def load(name: str):
    """The sequence and its reference poses (NaN where there is none)."""
    from navkit import datasets
    from navkit.io.rgbd import open_rgbd_sequence
    from navkit.io.trajectory import read_tum
    from navkit.planes.metrics import poses_at

    root = datasets.find(name)
    seq = open_rgbd_sequence(root)
    if seq.reference is not None:
        return seq, np.asarray(seq.reference)
    tr = read_tum(root / "groundtruth.txt")
    return seq, poses_at(seq.timestamps, tr.timestamps, tr.poses)


def main() -> None:
    from navkit.planes.gates_calibration import gates_from, passes, right_wrong, spoiled_alignments
    from navkit.planes.odometry import DenseGates

    results = {}
    for label, name in SEQUENCES.items():
        seq, G = load(name)
        results[label] = A = spoiled_alignments(seq.frame, G, list(range(10, 85, 8)))
        right, wrong = right_wrong(A)
        R = A[right]
        print(
            f"{label}: {len(A)} results, {right.sum()} right, {wrong.sum()} wrong; right: "
            f"geometric <= {np.nanmax(R[:, 2]):.2f} sigma, photometric <= "
            f"{np.nanmax(R[:, 3]):.1f} sigma, overlap >= {np.nanmin(R[:, 4]):.2f}, inliers >= "
            f"{np.nanmin(R[:, 5]):.2f}"
        )
    print("\n| gates | checked on | right passing | wrong passing (largest error) |")
    print("|---|---|---|---|")
    rows = [("default DenseGates", DenseGates(), lbl) for lbl in SEQUENCES]
    for src, dst in (("7-Scenes", "TUM"), ("TUM", "7-Scenes")):
        rows.append((f"from {src}", gates_from(results[src]), dst))
        rows.append((f"from {src}, no photometric", gates_from(results[src], False), dst))
    for name, gates, dst in rows:
        A = results[dst]
        right, wrong = right_wrong(A)
        ok = passes(gates, A)
        bad = A[wrong & ok]
        worst = f" ({100 * bad[:, 0].max():.1f} cm / {bad[:, 1].max():.1f} deg)" if len(bad) else ""
        print(
            f"| {name} | {dst} | {int((ok & right).sum())} / {int(right.sum())} | "
            f"{len(bad)} / {int(wrong.sum())}{worst} |"
        )


if __name__ == "__main__":
    main()
