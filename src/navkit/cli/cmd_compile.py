"""``navkit compile``: compile every kernel now (a robot's image, a container build, a CI cache).

Under the default policy (``NAVKIT_JIT=auto``, :mod:`navkit.jit`) a process on a machine where
navkit's kernels were never compiled runs their NumPy twins and compiles the kernels in the
background for the next run. ``navkit compile`` does that compilation in the foreground
(:func:`navkit.runtime.warmup.warm_up`) and writes the stamp; ``--status`` only reports.
"""

from __future__ import annotations

import typer

from navkit.cli.common import cli_errors, progress


def register(app: typer.Typer) -> None:
    @app.command("compile")
    def compile_kernels(
        status: bool = typer.Option(
            False, "--status", help="Only say whether the kernels are compiled on this machine."
        ),
    ) -> None:
        """Compile navkit's Numba kernels into the on-disk cache (about a minute of CPU, once).

        Example: navkit compile
        """
        with cli_errors():
            from navkit import jit

            if status:
                st = jit.status()
                state = (
                    "compiled"
                    if st.compiled
                    else "warming up"
                    if st.warming
                    else f"background compilation failed ({jit.failed_path()})"
                    if st.failed
                    else "not compiled"
                )
                typer.echo(f"kernels: {state}; policy NAVKIT_JIT={st.mode}; stamp {st.stamp}")
                return
            from navkit.runtime.warmup import warm_up

            res = warm_up(progress=progress)
            typer.echo(
                f"compiled {res.compiled} kernel specialisations, loaded {res.loaded} from the "
                f"cache in {sum(res.seconds.values()):.1f} s; stamp {res.stamp}"
            )
