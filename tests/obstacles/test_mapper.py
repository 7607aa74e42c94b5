"""ObstacleMapper (paper 1's online object): the same map as the mission's fusion made before it
moved out of the mission, and the map against the simulator's true footprints."""

from __future__ import annotations

import numpy as np
import pytest

from navkit.errors import ConfigError, InputError
from navkit.geometry import se3_from_rt
from navkit.obstacles import ObstacleMapper, ObstacleMapperSettings, detect_obstacles
from navkit.obstacles.evaluate import score_obstacle_map
from navkit.sim import SpinningLidar, load_scene, render_scan
from navkit.sim.footprints import true_footprints
from navkit.sim.scanners import RangeNoise

# The first 12 m of the yard's built-in route (navkit/data/mission_yard.toml), a scan every 1.5 m.
WAYPOINTS = np.array([[0.0, 0.0], [4.0, -0.4], [8.0, -0.6], [12.0, -1.0]])
# Computed with the mission's own fusion that this mapper replaces (navkit.mission.obstacle_map
# .ObstacleGrid as of 2026-11-22, fed exactly as run_mission fed it) on the same scans:
BEFORE = {"hits": 1959, "seen": 36804, "occupied": 489, "components": 10}
BEFORE_CENTROID = (8.7927, -2.4972)


def yard_scans():
    """Eight scans of the mission's lidar (24 x 480, the small settings) at true poses."""
    scene = load_scene("yard")
    lidar = SpinningLidar(n_beams=24, n_columns=480, elevation_min_deg=-24.8, elevation_max_deg=2.0)
    noise, rng = RangeNoise(0.002, 0.01, 0.01), np.random.default_rng(11)
    for k in range(8):
        s = 1.5 * k
        seg = min(int(s // 4.0), 2)
        d = WAYPOINTS[seg + 1] - WAYPOINTS[seg]
        p = WAYPOINTS[seg] + (s - 4.0 * seg) / 4.0 * d
        th = float(np.arctan2(d[1], d[0]))
        c, sn = np.cos(th), np.sin(th)
        R = np.array([[c, -sn, 0.0], [sn, c, 0.0], [0.0, 0.0, 1.0]])
        T = se3_from_rt(R, [p[0], p[1], float(scene.ground_height(*p)) + 1.2])
        sim = render_scan(scene, lidar, T, noise, rng, 40.0, 0.0)
        T2 = np.array([[c, -sn, p[0]], [sn, c, p[1]], [0.0, 0.0, 1.0]])
        yield scene, sim, detect_obstacles(sim.scan), T2, T


@pytest.fixture(scope="module")
def yard():
    return list(yard_scans())


def test_mapper_gives_the_map_the_mission_made_before(yard):
    """Same scans, same fusion: the counts agree with the old code path. The scans are seeded and
    every step is deterministic, so today they are identical; the 1 % / one-cell margins only
    absorb float-level changes of the detector's compiled kernels (a changed cell or two)."""
    mapper = ObstacleMapper([-5.0, -8.0], [20.0, 8.0], ObstacleMapperSettings())
    for _, _, det, T2, _ in yard:
        mapper.update(det, T2)
    g = mapper.grid()
    assert g.hits.sum() == pytest.approx(BEFORE["hits"], rel=0.01)
    assert g.seen.sum() == pytest.approx(BEFORE["seen"], rel=0.01)
    assert g.occupied.sum() == pytest.approx(BEFORE["occupied"], rel=0.01)
    assert len(mapper.obstacles()) == BEFORE["components"]
    rows, cols = np.nonzero(g.occupied)
    centroid = g.centres(rows, cols).mean(axis=0)
    assert np.hypot(*(centroid - BEFORE_CENTROID)) <= g.resolution
    # the snapshot is a copy
    mapper.add_points(np.zeros((0, 2)), np.zeros((0, 2)))
    assert mapper.n_scans == len(yard) + 1 and g.hits.sum() == mapper.hits.sum()


def test_a_level_3d_pose_gives_the_same_map_as_the_planar_one(yard):
    m2 = ObstacleMapper([-5.0, -8.0], [20.0, 8.0])
    m3 = ObstacleMapper([-5.0, -8.0], [20.0, 8.0])
    for _, _, det, T2, T3 in yard:
        m2.update(det, T2)
        m3.update(det, T3)
    # 3D rotation then projection vs the planar one: equal up to cells hit on a boundary
    assert (m2.occupied != m3.occupied).sum() <= 0.01 * m2.occupied.sum()


def test_every_obstacle_in_view_is_on_the_map(yard):
    """Against the simulator's truth: every isolated obstacle (paper 1's subject: not a wall or a
    building face) that at least 2 scans hit within the fusion range and taller than 0.3 m (a curb
    is traversable) is found within 0.3 m, and no component is a phantom further than 0.6 m from
    every footprint (walls included)."""
    mapper = ObstacleMapper([-5.0, -8.0], [20.0, 8.0])
    hits_per_prim: dict[int, int] = {}
    scene = yard[0][0]
    for _, sim, det, T2, _ in yard:
        mapper.update(det, T2)
        ok = sim.scan.valid & (sim.true_ranges <= mapper.settings.max_range)
        for k in np.unique(sim.hit_index[ok]).tolist():
            hits_per_prim[k] = hits_per_prim.get(k, 0) + 1
    seen = {k for k, n in hits_per_prim.items() if n >= 2}
    fps = true_footprints(scene)
    isolated = [f for f in fps if f.kind != "wall"]
    tight = score_obstacle_map(
        mapper.grid(), isolated, seen, min_height=0.3, robot_width=0.5, tolerance=0.3
    )
    assert tight["seen_obstacles"] >= 3
    assert tight["recall"] == 1.0, [r for r in tight["obstacles"] if r["seen"] and not r["found"]]
    loose = score_obstacle_map(
        mapper.grid(), fps, seen, min_height=0.0, robot_width=0.5, tolerance=0.6
    )
    assert loose["phantoms"] == 0, loose["component_list"]


def test_bad_settings_and_poses_are_named():
    with pytest.raises(ConfigError, match="min_ratio"):
        ObstacleMapperSettings(min_ratio=1.5)
    with pytest.raises(ConfigError, match="resolution"):
        ObstacleMapperSettings(resolution=0.0)
    mapper = ObstacleMapper([0, 0], [1, 1])
    det = next(yard_scans())[2]
    with pytest.raises(InputError, match="T_world_sensor"):
        mapper.update(det, np.eye(2))


def _box_of(seen):
    rows, cols = np.nonzero(seen)
    return [rows.min(), rows.max(), cols.min(), cols.max()] if rows.size else None


def _occupancy_reference(mapper):
    """The occupancy grid from whole-grid arrays: -1 never seen, 0 seen, 100 confirmed."""
    occ = np.where(mapper.seen > 0, 0, -1).astype(np.int8)
    occ[mapper.occupied] = 100  # hits >= min_hits and hits / max(seen, 1) >= min_ratio
    return occ


def test_the_read_outs_scan_the_window_of_the_cells_seen(yard):
    """:meth:`ObstacleMapper.window` is the smallest box of the cells seen (through
    :meth:`~ObstacleMapper.update` and :meth:`~ObstacleMapper.add_points`, and kept by a
    checkpoint or rebuilt from ``seen`` by a state without it), and the read-outs restricted to
    it (:meth:`~ObstacleMapper.occupied_cells`, :meth:`~ObstacleMapper.occupancy`) equal their
    definitions on the whole grid."""
    import pickle

    st = ObstacleMapperSettings()
    mapper = ObstacleMapper([-30.0, -30.0], [40.0, 30.0], st)  # beyond max_range of the route
    assert mapper.window() == (slice(0, 0), slice(0, 0))
    assert mapper.occupied_cells().size == 0 and (mapper.occupancy() == -1).all()
    for k, (_, _, det, T2, T3) in enumerate(yard):
        mapper.update(det, T2 if k % 2 else T3)
        rows, cols = mapper.window()
        assert [rows.start, rows.stop - 1, cols.start, cols.stop - 1] == _box_of(mapper.seen)
        h = mapper.hits.reshape(-1)
        ratio = h / np.maximum(mapper.seen.reshape(-1), 1)
        want = np.flatnonzero((h >= st.min_hits) & (ratio >= st.min_ratio))
        got = mapper.occupied_cells()
        assert got.dtype == want.dtype and np.array_equal(got, want)
        np.testing.assert_array_equal(mapper.occupancy(), _occupancy_reference(mapper))
    assert len(want) > 0 and (mapper.occupancy() == 0).any()  # not vacuous
    # the area's first and last cells, given as map points: the window grows to hold them
    assert mapper.window() != (slice(0, mapper.shape[0]), slice(0, mapper.shape[1]))
    mapper.add_points(np.array([[40.05, 30.05]]), np.array([[-29.95, -29.95], [40.05, 30.05]]))
    rows, cols = mapper.window()
    assert (rows, cols) == (slice(0, mapper.shape[0]), slice(0, mapper.shape[1]))
    assert [rows.start, rows.stop - 1, cols.start, cols.stop - 1] == _box_of(mapper.seen)
    np.testing.assert_array_equal(mapper.occupancy(), _occupancy_reference(mapper))
    clone = pickle.loads(pickle.dumps(mapper))
    assert clone.window() == mapper.window()
    del clone.__dict__["_box"]  # a state without the window: rebuilt from seen
    assert clone.window() == mapper.window()
