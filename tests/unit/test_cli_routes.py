"""One route per command: every command's CLI function parses, calls its API function and
prints; it never reaches past the API into compute, config loading or the report writers.

The check reads cli/ (no command runs): for each command of ``cli.main.COMMANDS`` it collects
every ``ema_cli`` import in the command function and in the cli/ helpers it calls (followed
transitively), and requires the API function of its route among them and nothing from a compute
layer, the config loader or a report writer (``run_*``, ``write_*``, ``save_*``, ``finish_*``,
``prepare_*``).
"""

from __future__ import annotations

import ast
import importlib
import inspect
import textwrap
from collections.abc import Callable, Iterator

import pytest

from ema_cli.cli import main

ROUTES = {
    "simulate": "ema_cli.api.simulation.simulate",
    "sweep": "ema_cli.api.study.sweep",
    "show": "ema_cli.api.study.plan",
    "threshold": "ema_cli.api.threshold.threshold",
    "margins": "ema_cli.api.margins.margins",
    "freqresp": "ema_cli.api.freqresp.freqresp",
    "acceptance": "ema_cli.api.acceptance.acceptance",
    "yield": "ema_cli.api.production.production_yield",
    "tune": "ema_cli.api.tune.tune",
    "sensitivity": "ema_cli.api.sensitivity.sensitivity",
    "identify": "ema_cli.api.identification.identify",
    "design": "ema_cli.api.design.design",
    "reproduce": "ema_cli.api.reproduce.reproduce",
    "compile": "ema_cli.api.kernels",
}
"""The API function each command's route goes through."""

NO_ROUTE = {
    "validate": "checks a config file against its schema (config/ models, one per kind); "
                "computes and writes nothing",
    "locations": "prints the nonlinearity table of model/ (a lookup, no computation)",
    "params": "prints the parameter table of model/ (a lookup, no computation)",
}
"""Commands without a compute route, each with the reason."""

COMPUTE = ("sweep", "sensitivity", "analysis", "identify", "tune", "acceptance", "optim", "sim",
           "model", "production")
"""Folders of ema_cli a command may reach only through the API."""
WRITERS = ("run_", "write_", "save_", "finish_", "prepare_", "compute_")
"""Report functions that write or run: the API calls them, a command never does."""
ALLOWED_MODEL = {"ema_cli.model.params.BY_NAME", "ema_cli.model.nonlinearities.lookup",
                 "ema_cli.model.nonlinearities.nonlinearity_updates",
                 "ema_cli.model.params.resolve", "ema_cli.config.loader.parse_value",
                 "ema_cli.identify.torque.problem.PARAM_UNITS",
                 "ema_cli.identify.closed_loop.problem.DEFAULT_FREE",
                 "ema_cli.config.loader.read_yaml"}
"""Table lookups used to parse and check options (units, names, defaults), not computation."""


def _imports(fn: Callable) -> Iterator[str]:
    """``module.name`` of every ``from ema_cli... import name`` in ``fn`` and, transitively, in
    the cli/ functions it calls by name."""
    seen: set[Callable] = set()
    todo = [fn]
    while todo:
        f = todo.pop()
        if f in seen:
            continue
        seen.add(f)
        tree = ast.parse(textwrap.dedent(inspect.getsource(f)))
        module = inspect.getmodule(f)
        for node in ast.walk(tree):
            if isinstance(node, ast.ImportFrom) and (node.module or "").startswith("ema_cli"):
                for alias in node.names:
                    yield f"{node.module}.{alias.name}"
                    if node.module.startswith("ema_cli.cli"):  # a cli/ helper: followed too
                        helper = getattr(importlib.import_module(node.module), alias.name, None)
                        if inspect.isfunction(helper):
                            todo.append(helper)
            elif isinstance(node, ast.Call) and isinstance(node.func, ast.Name):
                callee = getattr(module, node.func.id, None)
                if (inspect.isfunction(callee)
                        and callee.__module__.startswith("ema_cli.cli")):
                    todo.append(callee)


def _violations(name: str) -> list[str]:
    fn = dict(main.COMMANDS)[name]
    names = set(_imports(fn))
    bad = []
    for full in sorted(names - ALLOWED_MODEL):
        parts = full.split(".")
        if parts[1] in COMPUTE or full.startswith("ema_cli.config.loader"):
            bad.append(f"{full} (compute or config loading: go through the API)")
        elif parts[1] == "report" and parts[-1].startswith(WRITERS):
            bad.append(f"{full} (a report writer: the API calls it)")
    if name in ROUTES and ROUTES[name] not in names:
        bad.append(f"does not call {ROUTES[name]}")
    return bad


@pytest.mark.parametrize("name", [n for n, _ in main.COMMANDS])
def test_every_command_goes_through_its_api_function(name):
    if name in NO_ROUTE:
        assert name not in ROUTES
        return
    assert name in ROUTES, f"`ema {name}`: add its API function to ROUTES"
    assert _violations(name) == [], f"`ema {name}`"


def test_the_check_sees_a_command_that_skips_the_api():
    def rogue_cmd() -> None:
        from ema_cli.report.sweep_report import save_sweep  # noqa: F401
        from ema_cli.sweep.run import compute_sweep  # noqa: F401

    found = set(_imports(rogue_cmd))
    assert found == {"ema_cli.report.sweep_report.save_sweep", "ema_cli.sweep.run.compute_sweep"}
    bad = [f for f in found if f.split(".")[1] in COMPUTE
           or f.split(".")[-1].startswith(WRITERS)]
    assert len(bad) == 2


SUB_ROUTES = {
    ("identify", "torque"): "ema_cli.api.identification.identify",
    ("identify", "closed-loop"): "ema_cli.api.identify_logs.identify_closed_loop",
    ("identify", "friction-sweep"): "ema_cli.api.identify_logs.identify_friction_sweep",
    ("identify", "make-data"): "ema_cli.api.identify_logs.make_identification_data",
    ("identify", "plant"): "ema_cli.api.identify_plant.identify_plant",
    ("identify", "validate"): "ema_cli.api.identify_plant.validate_folder",
}
"""The API function each subcommand's route goes through (cli.main.GROUPS)."""


@pytest.mark.parametrize(("group", "sub"), [(g, n) for g, (subs, _) in main.GROUPS.items()
                                            for n, _ in subs])
def test_every_subcommand_goes_through_its_api_function(group, sub):
    assert (group, sub) in SUB_ROUTES, f"`ema {group} {sub}`: add its API function to SUB_ROUTES"
    fn = dict(main.GROUPS[group][0])[sub]
    names = set(_imports(fn))
    bad = [f for f in sorted(names - ALLOWED_MODEL)
           if f.split(".")[1] in COMPUTE or f.startswith("ema_cli.config.loader")
           or (f.split(".")[1] == "report" and f.split(".")[-1].startswith(WRITERS))]
    assert bad == [] and SUB_ROUTES[(group, sub)] in names, f"`ema {group} {sub}`: {bad}"
