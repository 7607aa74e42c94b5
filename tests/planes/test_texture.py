"""Textures: brightness on the plane's grid equals the simulated albedo; both sampling routes agree."""

from __future__ import annotations

import numpy as np

from navkit.geometry import se3_inverse
from navkit.planes import ExtractionSettings, observe_points, observe_rgbd
from navkit.sim.render import AMBIENT, SUN_DIRECTION

from .conftest import BRICKS, CAMERA

ES = ExtractionSettings(cell=10)


def wall_truth(pair, tex, footprint=0.0076):
    """Expected brightness at the texture's grid points: the brick albedo of the wall y = -1.5
    (surface coordinates: a = x + 5, b = z) times its Lambertian shading, as gray, averaged over
    one camera pixel's footprint (2 m / 262.5 px = 7.6 mm: the rendered image cannot be sharper)."""
    T = pair.f1.T_world_camera
    P = tex.points().reshape(-1, 3) @ T[:3, :3].T + T[:3, 3]
    offs = (np.arange(4) + 0.5) / 4 - 0.5
    rgb = np.mean(
        [
            BRICKS.evaluate(P[:, 0] + 5.0 + du * footprint, P[:, 2] + dv * footprint)
            for du in offs
            for dv in offs
        ],
        axis=0,
    )
    n = np.array([0.0, 1.0, 0.0])  # facing the camera
    shade = AMBIENT + (1 - AMBIENT) * np.clip(n @ SUN_DIRECTION, 0, 1)
    gray = (rgb * shade) @ np.array([0.299, 0.587, 0.114])
    return gray.reshape(tex.image.shape)


def test_texture_is_the_wall_albedo(pairs):
    pair = pairs[1]
    obs = observe_rgbd(pair.f1.frame, ES)
    tex = obs.texture(0, nu=0.01)
    assert tex.valid_count > 10_000
    truth = wall_truth(pair, tex)
    m = tex.mask
    # the camera blurs bricks (pixel footprint ~ 7.6 mm at 2 m, bilinear sampling): compare
    # after the same 1-pixel blur on both sides is unnecessary - the correlation is the measure
    r = np.corrcoef(tex.image[m], truth[m])[0, 1]
    assert r > 0.9
    # and brightness agrees to within the 8-bit quantisation plus edge blur, on average
    assert np.median(np.abs(tex.image[m] - truth[m])) < 0.02


def test_rgbd_and_calibrated_camera_routes_agree(pairs):
    """A range image plus a camera given by its extrinsics (here: identity) = registered RGB-D."""
    pair = pairs[1]
    f = pair.f1.frame
    a = observe_rgbd(f, ES)
    b = observe_points(
        f.points(), gray=f.color, camera=CAMERA, T_camera_sensor=np.eye(4), organized_settings=ES
    )
    ta, tb = a.texture(0), b.texture(0)
    assert np.array_equal(ta.index0, tb.index0) and ta.image.shape == tb.image.shape
    both = ta.mask & tb.mask
    assert both.sum() > 0.9 * ta.mask.sum()
    assert np.allclose(ta.image[both], tb.image[both], atol=1e-6)


def test_texture_from_a_moved_camera_matches(pairs):
    """The same world lattice sampled from the second view gives the same brightness."""
    pair = pairs[1]
    o1 = observe_rgbd(pair.f1.frame, ES)
    o2 = observe_rgbd(pair.f2.frame, ES)
    t1 = o1.texture(0)
    T12 = se3_inverse(pair.f1.T_world_camera) @ pair.f2.T_world_camera
    R, t = T12[:3, :3], T12[:3, 3]
    t2 = o2.texture(0, axes=t1.axes @ R, ref=R.T @ (t1.ref - t))
    lo = np.maximum(t1.index0, t2.index0)
    hi = np.minimum(t1.index0 + t1.image.shape[::-1], t2.index0 + t2.image.shape[::-1])
    a = t1.image[
        lo[1] - t1.index0[1] : hi[1] - t1.index0[1], lo[0] - t1.index0[0] : hi[0] - t1.index0[0]
    ]
    b = t2.image[
        lo[1] - t2.index0[1] : hi[1] - t2.index0[1], lo[0] - t2.index0[0] : hi[0] - t2.index0[0]
    ]
    m = np.isfinite(a) & np.isfinite(b)
    assert m.sum() > 5000
    # each view correlates > 0.9 with the (blurred) albedo; their blurs differ (other distance
    # and obliquity), so with each other > 0.9^2 ~ 0.8
    assert np.corrcoef(a[m], b[m])[0, 1] > 0.8


def test_uniform_plane_has_zero_contrast():
    from navkit.sim import render_rgbd

    from .conftest import SOLID, corridor, start_pose

    f = render_rgbd(corridor(1, SOLID), CAMERA, start_pose(1)).frame
    tex = observe_rgbd(f, ES).texture(0)
    assert tex.contrast() < 1e-3


def test_range_sensor_with_a_separate_camera(pairs):
    """Depth from view 1, colour from a camera 10 cm and 3 deg away (known extrinsics): the
    texture equals the one of the registered view-1 colour on the same lattice."""
    from scipy.spatial.transform import Rotation

    from navkit.geometry import se3_from_rt
    from navkit.sim import render_rgbd

    pair = pairs[1]
    T_w_1 = pair.f1.T_world_camera
    T_1_cam = se3_from_rt(Rotation.from_rotvec([0.0, 0.05, 0.0]).as_matrix(), [0.1, 0.02, 0.0])
    cam_frame = render_rgbd(pair.scene, CAMERA, T_w_1 @ T_1_cam).frame
    f1 = pair.f1.frame
    registered = observe_rgbd(f1, ES)
    separate = observe_points(
        f1.points(),
        gray=cam_frame.color,
        camera=CAMERA,
        T_camera_sensor=se3_inverse(T_1_cam),
        organized_settings=ES,
    )
    a, b = registered.texture(0), separate.texture(0)
    assert np.array_equal(a.index0, b.index0)
    both = a.mask & b.mask
    assert both.sum() > 0.8 * a.mask.sum()
    # same wall albedo seen through two cameras: correlation as for two views (> 0.8)
    assert np.corrcoef(a.image[both], b.image[both])[0, 1] > 0.8
    # a wrong extrinsic (the camera assumed at the depth sensor) breaks the agreement
    wrong = observe_points(
        f1.points(),
        gray=cam_frame.color,
        camera=CAMERA,
        T_camera_sensor=np.eye(4),
        organized_settings=ES,
    ).texture(0)
    m = a.mask & wrong.mask
    assert np.corrcoef(a.image[m], wrong.image[m])[0, 1] < 0.5


def test_a_shared_pyramid_gives_the_same_textures(pairs):
    """The frame's textures share one brightness pyramid (``PlaneObservation.texture``); each
    equals the texture sampled from the image alone, at every pyramid level the texel size
    asks for (1, 2, 4 cm)."""
    from navkit.planes.texture import texture_from_rgbd

    obs = observe_rgbd(pairs[1].f1.frame, ES)
    for nu in (0.01, 0.02, 0.04):
        shared = obs.texture(0, nu=nu)
        alone = texture_from_rgbd(
            obs.gray, obs.points, obs.extraction.labels, 0, obs.segments[0], obs.camera, nu
        )
        assert np.array_equal(shared.mask, alone.mask)
        assert np.array_equal(shared.image, alone.image, equal_nan=True)
