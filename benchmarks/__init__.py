"""Side-by-side benchmarks with the peers named in the issues (``make bench``).

Each module ``benchmarks/bench_<area>.py`` defines ``run(quick: bool = False) -> list[Row]``.
``python -m benchmarks [AREA ...] [--quick]`` runs them, prints one table and writes
``out/bench/<area>.json``. Timings are medians of repeats after a warm-up, on this machine.
"""

import os

# Benchmarks time the compiled kernels (or compare them with their NumPy twins explicitly): they
# compile on first use whatever the machine's cache holds (navkit.jit's "eager" policy).
os.environ.setdefault("NAVKIT_JIT", "eager")
