"""The dense gates in noise units transfer between sensors and scenes
(:mod:`navkit.planes.gates_calibration`; ``python -m benchmarks.planes_gates`` runs the full
protocol both ways). Calibrated on 7-Scenes, gates accept the TUM frames' right alignments. The
reverse holds for the depth gates only: 7-Scenes' colour is not registered with its depth
(edges misalign by several pixels), so its right alignments keep up to ~15 brightness sigmas
where TUM's keep ~3.5 - which is why the default photometric gate (20 sigmas) is a sanity bound
and the depth terms, in the depth noise model's sigmas, decide.
"""

from __future__ import annotations

import numpy as np
import pytest

from navkit.planes.gates_calibration import gates_from, passes, right_wrong, spoiled_alignments
from navkit.planes.metrics import poses_at
from navkit.planes.odometry import DenseGates

STARTS = [10, 34, 58]


@pytest.fixture(scope="module")
def results():
    from navkit import datasets
    from navkit.errors import DataNotFoundError
    from navkit.io.rgbd import open_rgbd_sequence
    from navkit.io.trajectory import read_tum

    def data_path(relative: str):
        try:
            return datasets.find(relative)
        except DataNotFoundError as exc:
            pytest.skip(f"recorded data absent: {exc}")

    seven = open_rgbd_sequence(data_path("rgbd/7scenes-tsdf"))
    root = data_path("rgbd/tum-fr3-structure-notexture-far")
    tum = open_rgbd_sequence(root)
    tr = read_tum(root / "groundtruth.txt")
    G = poses_at(tum.timestamps, tr.timestamps, tr.poses)
    return {
        "7-Scenes": spoiled_alignments(seven.frame, seven.reference, STARTS),
        "TUM": spoiled_alignments(tum.frame, G, STARTS),
    }


@pytest.mark.realdata
def test_the_depth_noise_model_holds_on_both_sequences(results):
    """Right alignments leave point-to-plane residuals of about one modelled depth sigma on
    both Kinect recordings (a perfect alignment under a right noise model gives 1; measured
    0.4-1.0 on 7-Scenes, 0.4-0.8 on TUM), and overlap and inliers stay high: the depth gates
    (1.5 sigma, overlap 0.3, inliers 0.6) have margin on both without being set per sequence.
    Gates derived from the 7-Scenes alignments alone accept every right TUM alignment."""
    for label, A in results.items():
        right, _ = right_wrong(A)
        R = A[right]
        assert right.sum() >= 20, label
        assert 0.2 <= np.median(R[:, 2]) <= 1.0 and R[:, 2].max() <= 1.25, (label, R[:, 2])
        assert R[:, 4].min() >= 0.8 and R[:, 5].min() >= 0.95, label
    right, _ = right_wrong(results["TUM"])
    assert passes(gates_from(results["7-Scenes"]), results["TUM"])[right].all()


@pytest.mark.realdata
def test_default_gates_accept_every_right_alignment_and_no_far_wrong_one(results):
    """The default gates on both sequences: every right alignment passes; no wrong one off by
    more than 15 cm or 5 deg does (measured: the worst that passes is 10 cm / 0.6 deg, from an
    80 cm / 20 deg start in TUM's repeating zig-zag, which no odometry start is near)."""
    for label, A in results.items():
        right, _ = right_wrong(A)
        ok = passes(DenseGates(), A)
        assert ok[right].all(), label
        far = (A[:, 0] > 0.15) | (A[:, 1] > 5.0)
        assert not (ok & far).any(), (label, A[ok & far])
