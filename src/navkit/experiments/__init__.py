"""Reproducible experiments of the papers, shared by the tests and the benchmarks.

:mod:`navkit.experiments` is a top-level package beside :mod:`navkit.mission`: it sits above the
capabilities and may import :mod:`navkit.sim`, :mod:`navkit.io`, :mod:`navkit.datasets` and any
capability (:mod:`navkit.obstacles`, ...), while no capability imports it. Each module holds one
paper's experiments - the simulated scenes, the scoring against the simulator's truth and the
helpers for the recorded data - so that ``tests/<area>`` and ``benchmarks/bench_<area>.py`` run
the same code instead of the tests importing from the ``benchmarks`` folder.
"""

__all__ = ["obstacles"]
