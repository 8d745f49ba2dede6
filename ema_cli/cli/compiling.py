"""`ema compile`: compile (or load from the cache) every kernel entry point in every variant,
so that no later command waits for the compiler (``make run`` runs it)."""

from __future__ import annotations

import typer

from ema_cli.cli.common import handle_errors


@handle_errors
def compile_cmd(
    jobs: int = typer.Option(2, "--jobs", "-j", min=1, max=64, metavar="N",
                             help="processes compiling at once (the unit families: one lane, "
                                  "SIMD lanes, identification; at most 3 are used)"),
) -> None:
    """Compile every kernel entry point and variant into the cache (first run after an
    install or an edit of the model or the kernel; then a second or two)."""
    import time

    from ema_cli.api import kernels
    from ema_cli.cli.common import err_console

    t0 = time.perf_counter()
    names = kernels.units()
    todo, shares, est = kernels.plan(jobs)
    if todo:
        procs = len(shares)
        err_console.print(f"compiling the simulator: {len(todo)} of {len(names)} units, "
                          f"~{est:.0f} s on {procs} process{'es' if procs > 1 else ''} "
                          "(first run only)")

    def done(name: str, sec: float, k: int, n: int) -> None:
        err_console.print(f"  [{k}/{n}] {kernels.describe(name)}: {sec:.1f} s")

    kernels.compile_all(jobs, done)
    missing = kernels.missing()
    if missing:
        from ema_cli.errors import EmaError

        raise EmaError(f"the compiled cache lacks {', '.join(missing)} after compiling; is "
                       "the cache folder writable? (EMA_CACHE_DIR)")
    typer.echo(f"kernels: all {len(names)} units compiled and cached "
               f"({time.perf_counter() - t0:.1f} s)")
