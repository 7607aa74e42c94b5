"""The obstacle map figure: footprints as concave outlines, shapes only round compact obstacles."""

from __future__ import annotations

import numpy as np

from navkit.viz.obstacles import footprint_outlines, plot_obstacle_map


def _area(poly):
    x, y = poly[:, 0], poly[:, 1]
    return 0.5 * abs(np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y))


def test_an_l_shaped_wall_is_outlined_not_boxed():
    t = np.arange(0.0, 10.0, 0.05)
    wall = np.vstack(
        [np.column_stack([t, np.zeros_like(t)]), np.column_stack([np.zeros_like(t), t])]
    )
    (outline,) = footprint_outlines(wall, cell_m=0.2, close_m=0.6)
    # the outline hugs the two 10 m walls (to within a 0.2 m cell and a half), and its area is
    # that of two thin strips, not the 50 m^2 triangle of the convex hull
    assert np.allclose(outline.min(axis=0), [0.0, 0.0], atol=0.3)
    assert np.allclose(outline.max(axis=0), [10.0, 10.0], atol=0.3)
    assert 1.0 < _area(outline) < 10.0
    # two blobs 5 m apart stay two outlines
    blobs = np.vstack([np.random.default_rng(0).normal(c, 0.1, (200, 2)) for c in ((0, 0), (5, 0))])
    assert len(footprint_outlines(blobs)) == 2


def test_shapes_only_round_compact_obstacles():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from navkit.experiments.obstacles import run_experiment

    det = run_experiment("four", "tilting", 0.01, 0).detection
    sides = [float(np.max(np.ptp(ob.polygon_xy, axis=0))) for ob in det.obstacles]
    fig, ax = plt.subplots()
    try:
        plot_obstacle_map(det, ax=ax, shapes=("A1", "A6"), max_shape_m=np.median(sides))
        compact = sum(s <= np.median(sides) for s in sides)
        shape_lines = [
            ln for ln in ax.lines if ln.get_label().startswith("_") and len(ln.get_xdata()) > 2
        ]
        assert len(shape_lines) == 2 * compact < 2 * len(sides)
        labels = {t.get_text() for t in ax.texts}
        assert labels == {str(ob.id) for ob in det.obstacles}  # every obstacle numbered
        assert any(
            "m" == t.get_text().split()[-1] for t in ax.artists[0].findobj(matplotlib.text.Text)
        )
    finally:
        plt.close(fig)
