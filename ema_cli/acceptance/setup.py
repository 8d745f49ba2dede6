"""The actuator each test of a spec runs on: the spec's actuator (a run config with overrides)
and each test's ``set:`` on top, resolved to SI parameters and a time step, every test checked
measurable before any simulation (``ema acceptance`` and ``ema yield`` alike)."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

from ema_cli.config.acceptance import AcceptanceSpec
from ema_cli.config.support import check_command
from ema_cli.errors import EmaError

Setup = tuple[dict[str, float], float]
"""An actuator's SI parameters and its simulation step [s]."""


def test_setups(sp: AcceptanceSpec, names: Sequence[str],
                folder: Path | None) -> tuple[Setup, dict[str, Setup]]:
    """The spec's actuator, and each named test's (the actuator with the test's ``set:`` on
    top), every test checked measurable before any simulation; ``folder``: where the spec's
    relative paths start (None: the working folder)."""
    from ema_cli.config.acceptance import check_measurable
    from ema_cli.config.loader import dotted_pairs, load_config, resolve_run
    from ema_cli.config.study import StudyConfig

    act_source, act_dir = sp.actuator.source(folder, "spec")
    base_pairs = sp.actuator.pairs()

    def resolved(extra: list[tuple[str, Any]], where: str) -> tuple[dict[str, float], float]:
        try:
            cfg = load_config(act_source, base_pairs + extra, StudyConfig)
            check_command(cfg, "acceptance")
        except EmaError as exc:
            raise EmaError(f"{where}: {exc}") from None
        run = resolve_run(cfg, act_dir)
        return run.params, run.dt

    actuator = resolved([], "actuator")
    setups = {}
    for name in names:  # every test's actuator and time step, checked before any simulation
        test = sp.tests[name]
        setups[name] = actuator if not test.overrides else resolved(
            dotted_pairs(test.overrides), f"tests.{name}.set")
        if test.test == "duty":  # its profile read and checked on this actuator first
            _check_profile(name, test, folder, setups[name])
        check_measurable(name, test, setups[name][1])
    return actuator, setups


def _check_profile(name: str, test: Any, folder: Path | None, setup: Setup) -> None:
    """A duty test's profile, read relative to the spec and expanded on the test's actuator
    (every key checked before any simulation): EmaError naming the test."""
    from ema_cli.acceptance.duty.profile import expand

    test.bind(folder)
    try:
        expand(test.load_profile(), "rotary", setup[0]["T_amb"],
               test.load_profile().simulation.dt_s or setup[1])
    except EmaError as exc:
        raise EmaError(f"tests.{name}.profile: {exc}") from None
