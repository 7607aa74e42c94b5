"""Figures (matplotlib, Agg backend, saved atomically). One module per area, e.g.
:mod:`navkit.viz.sensors` (what the simulated sensors saw, with the truth)."""
