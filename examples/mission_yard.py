"""All four capabilities on a simulated robot (the mission): out, detect, map, come home.

Runs the built-in "yard" route with reduced sensor resolutions and prints the mission's
headline figures, each against the simulator's ground truth. ``--waypoints N`` keeps the first N
waypoints of the route (and leaves out the room unless the route still reaches it): a quicker
outdoor out-and-back.

    python examples/mission_yard.py [--seed 0] [--waypoints 3]
"""

from __future__ import annotations

import argparse
from dataclasses import replace

from navkit.mission import (
    MissionSettings,
    builtin_route_path,
    load_route,
    mission_metrics,
    run_mission,
)
from navkit.sim import load_scene


def main(argv: list[str] | None = None) -> dict[str, float]:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--waypoints", type=int, default=0, help="keep the first N (0: all)")
    args = ap.parse_args(argv)

    route, overrides = load_route(builtin_route_path("yard"))
    if args.waypoints > 0:
        route = replace(route, waypoints=route.waypoints[: args.waypoints], room=None)
    settings = MissionSettings.small(seed=args.seed).with_overrides(overrides)
    log = run_mission(load_scene("yard"), route, settings)
    flat = _flatten(mission_metrics(log))
    for key, value in flat.items():
        if not key.startswith("timing."):
            print(f"{key}: {value:.4g}")
    return flat


def _flatten(d: dict, prefix: str = "") -> dict[str, float]:
    out: dict[str, float] = {}
    for key, value in d.items():
        if isinstance(value, dict):
            out.update(_flatten(value, f"{prefix}{key}."))
        elif isinstance(value, (int, float)) and not isinstance(value, bool):
            out[prefix + key] = float(value)
    return out


if __name__ == "__main__":
    main()
