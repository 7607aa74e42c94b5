"""Run the benchmarks: ``python -m benchmarks [AREA ...] [--quick]``."""

from __future__ import annotations

import argparse
import dataclasses
import importlib
import json
import pkgutil
import sys
import traceback
from pathlib import Path

import benchmarks
from benchmarks.common import Row


def _fmt(v: float | None) -> str:
    if v is None:
        return "-"
    return f"{v:.4g}"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m benchmarks")
    parser.add_argument("areas", nargs="*", help="which bench_<area> modules (default: all)")
    parser.add_argument("--quick", action="store_true", help="fewer repeats and frames")
    parser.add_argument("--out", default="out/bench", help="folder for the JSON results")
    args = parser.parse_args(argv)

    names = sorted(
        m.name[len("bench_") :]
        for m in pkgutil.iter_modules(benchmarks.__path__)
        if m.name.startswith("bench_")
    )
    selected = args.areas or names
    unknown = set(selected) - set(names)
    if unknown:
        parser.error(f"unknown areas {sorted(unknown)}; available: {names}")

    from rich.console import Console
    from rich.table import Table

    console = Console()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    failed = []
    all_rows: list[Row] = []
    for area in selected:
        console.print(f"[bold]bench {area}[/bold] ...")
        try:
            rows = importlib.import_module(f"benchmarks.bench_{area}").run(quick=args.quick)
        except Exception:  # report and go on with the other areas
            traceback.print_exc()
            failed.append(area)
            continue
        (out / f"{area}.json").write_text(
            json.dumps([dataclasses.asdict(r) for r in rows], indent=2)
        )
        all_rows.extend(rows)

    table = Table(title="navkit benchmarks (this machine)")
    for col in ("area", "benchmark", "unit", "navkit", "peer", "peer value", "ratio", "note"):
        table.add_column(col)
    for r in all_rows:
        table.add_row(
            r.area,
            r.benchmark,
            r.unit,
            _fmt(r.navkit),
            r.peer_name,
            _fmt(r.peer),
            _fmt(r.ratio),
            r.note,
        )
    console.print(table)
    if failed:
        console.print(f"[red]failed areas: {failed}[/red]")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
