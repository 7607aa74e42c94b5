"""``navkit mission sweep``: seeds on a LocalCluster give the figures of the seeds run one by one."""

from __future__ import annotations

import json

import pytest

from navkit.batch import parse_seeds
from navkit.errors import ConfigError
from navkit.mission.metrics import mission_metrics

# The corridor of tests/mission/conftest.py (closed_run), as the scene and mission files a user
# writes: a 2.2 m wide corridor closed behind the operator; a wall drops 3.5 m from the operator.
CORRIDOR = """
name = "corridor"
start = [0.0, 0.0, 0.0]
[[primitive]]
type = "ground"
name = "ground"
[primitive.texture]
kind = "noise"
scale = 1.5
seed = 7
color = [0.5, 0.49, 0.46]
color2 = [0.22, 0.22, 0.21]
"""
for _name, _origin, _u, _seed in (
    ("corridor_south", (-1.5, -1.1, 0.0), (10.5, 0.0, 0.0), 1),
    ("corridor_north", (-1.5, 1.1, 0.0), (10.5, 0.0, 0.0), 2),
    ("corridor_end", (-1.5, -1.1, 0.0), (0.0, 2.2, 0.0), 3),
):
    CORRIDOR += f"""
[[primitive]]
type = "wall"
name = "{_name}"
origin = {list(_origin)}
u = {list(_u)}
v = [0.0, 0.0, 2.0]
[primitive.texture]
kind = "noise"
scale = 0.4
seed = {_seed}
color = [0.8, 0.75, 0.7]
color2 = [0.3, 0.3, 0.28]
"""
MISSION = """
[route]
waypoints = [[0.0, 0.0], [7.0, 0.0]]
block_at = 3.5
block_size = [0.3, 2.4, 1.0]
"""


def test_parse_seeds():
    assert parse_seeds("3:6") == [3, 4, 5]
    assert parse_seeds("9") == [9]
    assert parse_seeds("1, 5") == [1, 5]
    for bad in ("", "5:5", "a:b", "-1:3", "1,1", "0:99999999"):
        with pytest.raises(ConfigError, match="seeds"):
            parse_seeds(bad)


@pytest.mark.slow
def test_sweep_on_two_workers_equals_the_mission_run_alone(cli, tmp_path, closed_run):
    pytest.importorskip(
        "distributed", reason="the cluster extra (dask.distributed) is not installed"
    )
    (tmp_path / "corridor.toml").write_text(CORRIDOR, encoding="utf-8")
    (tmp_path / "corridor.mission.toml").write_text(MISSION, encoding="utf-8")
    out = tmp_path / "sweep"
    r = cli(
        "mission", "sweep", tmp_path / "corridor.toml", "--seeds", "5:7", "--small",
        "--workers", "2", "--out", out,
    )  # fmt: skip
    assert r.exit_code == 0, r.output
    rows = [json.loads(line) for line in (out / "batch.jsonl").read_text().splitlines()]
    assert [(row["key"], row["status"]) for row in rows] == [("seed-5", "ok"), ("seed-6", "ok")]
    # seed 5 is the closed corridor of the mission tests, run there in process, one by one
    alone = mission_metrics(closed_run)
    fig = rows[0]["figures"]
    assert fig["final_distance_to_operator_m"] == alone["return"]["final_distance_to_operator_m"]
    assert fig["position_error_mean_m"] == alone["pose_error"]["corrected_m"]["mean"]
    assert fig["returned"] == (alone["return"]["outcome"] == "returned")
    on_disk = json.loads((out / "seed-5" / "metrics.json").read_text())
    assert on_disk["return"]["outcome"] == alone["return"]["outcome"]
    summary = json.loads((out / "batch_summary.json").read_text())
    assert summary["rates"]["returned"]["trials"] == 2
    lo, hi = summary["rates"]["returned"]["ci95"]
    assert lo <= summary["rates"]["returned"]["rate"] <= hi
