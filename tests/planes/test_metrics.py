"""ATE / RPE with evo's definitions, checked against evo itself."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from navkit.geometry import se3_from_rt
from navkit.planes.metrics import ate, rpe


def random_traj(rng, n=30):
    R = Rotation.from_rotvec(np.cumsum(rng.normal(0, 0.05, (n, 3)), axis=0)).as_matrix()
    t = np.cumsum(rng.normal(0, 0.1, (n, 3)), axis=0)
    return se3_from_rt(R, t)


def test_against_evo(rng):
    evo_sync = pytest.importorskip("evo.core.metrics")
    from evo.core.trajectory import PoseTrajectory3D

    ref = random_traj(rng)
    noise = se3_from_rt(
        Rotation.from_rotvec(rng.normal(0, 0.01, (30, 3))).as_matrix(), rng.normal(0, 0.02, (30, 3))
    )
    offset = se3_from_rt(Rotation.from_rotvec([0, 0, 0.7]).as_matrix(), [1.0, -2.0, 0.5])
    est = offset @ ref @ noise
    stamps = np.arange(30.0)
    tr = PoseTrajectory3D(poses_se3=list(ref), timestamps=stamps)
    te = PoseTrajectory3D(poses_se3=list(est), timestamps=stamps)
    te.align(tr, correct_scale=False)
    ape = evo_sync.APE(evo_sync.PoseRelation.translation_part)
    ape.process_data((tr, te))
    assert ate(est, ref) == pytest.approx(ape.get_statistic(evo_sync.StatisticsType.rmse), rel=1e-6)
    for rel, ours in (
        (evo_sync.PoseRelation.translation_part, 0),
        (evo_sync.PoseRelation.rotation_angle_deg, 1),
    ):
        m = evo_sync.RPE(rel, delta=1, delta_unit=evo_sync.Unit.frames, all_pairs=False)
        m.process_data(
            (
                PoseTrajectory3D(poses_se3=list(ref), timestamps=stamps),
                PoseTrajectory3D(poses_se3=list(est), timestamps=stamps),
            )
        )
        assert rpe(est, ref)[ours] == pytest.approx(
            m.get_statistic(evo_sync.StatisticsType.rmse), rel=1e-6
        )


def test_identical_trajectories_have_zero_error(rng):
    T = random_traj(rng)
    assert ate(T, T) == pytest.approx(0, abs=1e-9)
    assert rpe(T, T) == pytest.approx((0, 0), abs=1e-6)
