"""The README's Python example runs as written and prints what it claims."""

import re
from pathlib import Path

import numpy as np
from scipy.integrate import quad

README = Path(__file__).resolve().parents[2] / "README.md"


def test_readme_example_runs(capsys):
    blocks = re.findall(r"```python\n(.*?)```", README.read_text(), flags=re.S)
    assert blocks, "the README has a Python example"
    exec(compile(blocks[0], "README.md", "exec"), {})
    out = capsys.readouterr().out
    n_obstacles = int(re.search(r"(\d+) obstacles", out).group(1))
    assert n_obstacles >= 6  # the yard has walls, 3 crates, a rock, a ramp, a post, a ball
    length = float(re.search(r"([\d.]+) m of path", out).group(1))
    # arc length of (t, sin(t/2)), t in [0, 20]; the spline stays within eps = 5 cm of it
    exact, _ = quad(lambda t: np.sqrt(1 + (0.5 * np.cos(t / 2)) ** 2), 0, 20)
    assert abs(length - exact) < 0.05
