"""A small world and mission for the tests: a yard with three obstacles and a room with a door.

Small enough that one whole mission (about 13 m out, the way back) runs in about 15 s on 2 cores;
the session-scoped fixtures run it once per scenario.
"""

from __future__ import annotations

import numpy as np
import pytest

from navkit.mission import MissionSettings, Route, run_mission
from navkit.sim import Box, Cylinder, Ground, Hemisphere, Scene, Texture, Wall

ROOM = (8.0, -3.0, 13.0, 3.0)
WAYPOINTS = ((0.0, 0.0), (4.0, 0.2), (7.0, 0.0), (9.0, 0.0), (10.5, -1.0), (11.5, -1.8))


def small_scene() -> Scene:
    noise = lambda seed, c: Texture("noise", scale=0.4, seed=seed, color=c, color2=(0.3, 0.3, 0.28))  # noqa: E731
    x0, y0, x1, y1 = ROOM
    h = 3.0
    return Scene(
        [
            Ground(
                name="ground",
                texture=Texture(
                    "noise", scale=1.5, seed=7, color=(0.5, 0.49, 0.46), color2=(0.22, 0.22, 0.21)
                ),
            ),
            Box(
                center=(3.0, 1.6, 0.5),
                size=(1.0, 1.0, 1.0),
                name="crate",
                texture=noise(1, (0.7, 0.5, 0.3)),
            ),
            Hemisphere(
                center=(5.0, -1.7, 0.0),
                radius=0.55,
                name="rock",
                texture=noise(2, (0.6, 0.6, 0.55)),
            ),
            Cylinder(center=(6.0, 1.3, 0.0), radius=0.1, height=1.2, name="post"),
            Box(
                center=(12.2, 2.2, 0.5),
                size=(0.8, 0.6, 1.0),
                name="cabinet",
                texture=noise(3, (0.5, 0.35, 0.2)),
            ),
            Wall(
                origin=(x0, y0, 0.0),
                u=(x1 - x0, 0.0, 0.0),
                v=(0.0, 0.0, h),
                name="room_south",
                texture=noise(11, (0.85, 0.8, 0.7)),
            ),
            Wall(
                origin=(x1, y0, 0.0),
                u=(0.0, y1 - y0, 0.0),
                v=(0.0, 0.0, h),
                name="room_east",
                texture=Texture("bricks", scale=0.25, seed=12),
            ),
            Wall(
                origin=(x0, y1, 0.0),
                u=(x1 - x0, 0.0, 0.0),
                v=(0.0, 0.0, h),
                name="room_north",
                texture=noise(13, (0.8, 0.84, 0.76)),
            ),
            Wall(
                origin=(x0, y0, 0.0),
                u=(0.0, 2.4, 0.0),
                v=(0.0, 0.0, h),
                name="room_west_south",
                texture=noise(14, (0.75, 0.7, 0.8)),
            ),
            Wall(
                origin=(x0, 0.6, 0.0),
                u=(0.0, 2.4, 0.0),
                v=(0.0, 0.0, h),
                name="room_west_north",
                texture=noise(15, (0.75, 0.7, 0.8)),
            ),
        ],
        name="small",
    )


def small_route(block_at: float | None = None) -> Route:
    return Route(waypoints=WAYPOINTS, room=ROOM, block_at=block_at)


@pytest.fixture(scope="session")
def mission_run():
    """The small mission, seed 3 (the defaults of the fusion were set on the yard with seed 0)."""
    scene = small_scene()
    return run_mission(scene, small_route(), MissionSettings.small(seed=3))


@pytest.fixture(scope="session")
def blocked_run():
    """The small mission with a box dropped on the outbound path, 5 m from the operator."""
    return run_mission(small_scene(), small_route(block_at=5.0), MissionSettings.small(seed=4))


CORRIDOR_HALF_WIDTH = 1.1


def corridor_scene() -> Scene:
    """A 2.2 m wide corridor, closed behind the operator (at x = -1.5), open at x = 9."""
    x0, x1, w = -1.5, 9.0, CORRIDOR_HALF_WIDTH

    def tex(seed):
        return Texture(
            "noise", scale=0.4, seed=seed, color=(0.8, 0.75, 0.7), color2=(0.3, 0.3, 0.28)
        )

    return Scene(
        [
            Ground(
                name="ground",
                texture=Texture(
                    "noise", scale=1.5, seed=7, color=(0.5, 0.49, 0.46), color2=(0.22, 0.22, 0.21)
                ),
            ),
            Wall(
                origin=(x0, -w, 0.0),
                u=(x1 - x0, 0, 0),
                v=(0, 0, 2.0),
                name="corridor_south",
                texture=tex(1),
            ),
            Wall(
                origin=(x0, w, 0.0),
                u=(x1 - x0, 0, 0),
                v=(0, 0, 2.0),
                name="corridor_north",
                texture=tex(2),
            ),
            Wall(
                origin=(x0, -w, 0.0),
                u=(0, 2 * w, 0),
                v=(0, 0, 2.0),
                name="corridor_end",
                texture=tex(3),
            ),
        ],
        name="corridor",
    )


@pytest.fixture(scope="session")
def closed_run():
    """7 m out along the corridor; on the way back a wall (a 0.3 m thick box as wide as the
    corridor and overlapping both walls) closes it 3.5 m from the operator."""
    route = Route(
        waypoints=((0.0, 0.0), (7.0, 0.0)),
        block_at=3.5,
        block_size=(0.3, 2 * CORRIDOR_HALF_WIDTH + 0.2, 1.0),
    )
    return run_mission(corridor_scene(), route, MissionSettings.small(seed=5))


@pytest.fixture
def np_rng():
    return np.random.default_rng(7)
