"""The viewer configurations shipped in ``docs/`` show every output ``navkit run`` writes: the
Foxglove layout (``docs/foxglove/navkit.json``) and the RViz2 config (``docs/rviz/navkit.rviz``)
configure exactly the result topics the stages publish (read from the stages' source, so a new
topic without a display fails here), with TF and the ``map`` frame."""

from __future__ import annotations

import json
import re
from pathlib import Path

import yaml

REPO = Path(__file__).resolve().parents[2]


def run_topics() -> set[str]:
    runtime = REPO / "src" / "navkit" / "runtime"
    # the stages of `navkit run` (the mission's sink publishes other topics)
    src = "".join((runtime / f).read_text() for f in ("capabilities.py", "planes_stage.py"))
    topics = set(re.findall(r'Output\(\s*"(/navkit/[^"]+)"', src))
    return topics - {"/navkit/planes/textured"}  # viewer only, not in results.mcap


def test_foxglove_layout_shows_every_output():
    want = run_topics()
    assert len(want) >= 11
    layout = json.loads((REPO / "docs" / "foxglove" / "navkit.json").read_text())
    panel = layout["configById"][layout["layout"]["first"]]
    assert panel["followTf"] == "map"
    assert set(panel["topics"]) == want
    assert all(t["visible"] for t in panel["topics"].values())
    assert panel["topics"]["/navkit/obstacles/points"]["colorField"] == "class"


def test_rviz_config_shows_every_output():
    want = run_topics()
    cfg = yaml.safe_load((REPO / "docs" / "rviz" / "navkit.rviz").read_text())
    vm = cfg["Visualization Manager"]
    assert vm["Global Options"]["Fixed Frame"] == "map"
    displays = vm["Displays"]
    assert "rviz_default_plugins/TF" in {d["Class"] for d in displays}
    got = {d["Topic"]["Value"] for d in displays if "Topic" in d}
    assert got == want
    qos = yaml.safe_load((REPO / "docs" / "rviz" / "qos_overrides.yaml").read_text())
    assert qos["/tf_static"]["durability"] == "transient_local"
