"""The documents ``ema design`` hands to its steps: ``--set`` pairs split by step, the tuning
config and the acceptance spec on the fitted actuator, the corners of the identified intervals
(``api.design`` runs the steps)."""

from __future__ import annotations

import copy
import itertools
import re
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from ema_cli.errors import EmaError

if TYPE_CHECKING:
    from ema_cli.api.acceptance import AcceptanceResult

FRICTION_OBSERVER = {"friction_ff_fc_nm": "Fc", "friction_ff_fs_nm": "Fs",
                     "friction_ff_vs_rad_s": "vs", "friction_ff_sigma2": "sigma2",
                     "friction_ff_sigma0": "sigma0", "friction_ff_sigma1": "sigma1"}
"""Run-config controller key of the friction observer -> the model parameter it estimates."""
SECTIONS = ("identify", "tune")


def actuator_name(log: str, case: str = "") -> str:
    """The fitted actuator's name in titles and folders: the log's stem (characters a folder
    name cannot hold replaced by ``-``) + ``-fitted`` (+ ``-CASE`` for an interval corner)."""
    from pathlib import Path

    stem = re.sub(r"[^A-Za-z0-9_.-]", "-", Path(log).stem)[:40].strip(".-") or "log"
    return f"{stem}-fitted" + (f"-{case}" if case and case != "nominal" else "")


def split_overrides(pairs: list[tuple[str, Any]]) -> dict[str, list[tuple[str, Any]]]:
    """``identify.KEY=V`` / ``tune.KEY=V`` pairs -> {section: [(KEY, V)]}; anything else is
    an error naming the key."""
    out: dict[str, list[tuple[str, Any]]] = {s: [] for s in SECTIONS}
    for k, v in pairs:
        head, _, rest = str(k).partition(".")
        if head == "name" and not rest:
            continue
        if head not in SECTIONS or not rest:
            raise EmaError(f"--set {k}: expected identify.KEY=VALUE (a setting of `ema identify "
                           "--closed-loop`) or tune.KEY=VALUE (a key of the tuning config)")
        out[head].append((rest, v))
    return out


def fitted_tune_document(tune_doc: dict[str, Any], plant: dict[str, Any],
                         full: dict[str, float], name: str | None = None
                         ) -> tuple[dict[str, Any], list[str]]:
    """The tuning config on the fitted actuator -> (document, notes on what changed).

    ``plant``: the fitted run config's plant (identified and fixed values); ``full``: every
    SI parameter of the fitted actuator (for the friction observer's estimates); ``name``:
    the fitted actuator's (titles of the tuning's report and figures)."""
    from ema_cli.config.loader import dotted_pairs
    from ema_cli.model.nonlinearities import nonlinearity_updates
    from ema_cli.model.params import resolve

    doc = copy.deepcopy(tune_doc)
    if name is not None:
        doc["name"] = name
    notes = []
    act = doc.get("actuator") or {}
    if act.get("config") or act.get("plant") or act.get("nonlinearities"):
        notes.append("tuning config: its actuator section is replaced by the fitted actuator")
    doc["actuator"] = {"config": None, "plant": dict(plant), "nonlinearities": {}}
    for name, sc in (doc.get("scenarios") or {}).items():
        if not isinstance(sc, dict):
            continue
        nls = dict(sc.get("nonlinearities") or {})
        for nl, value in list(nls.items()):
            try:
                touched = set(nonlinearity_updates(nl, value, resolve())) - {"friction"}
            except EmaError:
                continue  # the tuning config's own validation names it
            hit = sorted(touched & set(plant))
            if hit:
                del nls[nl]
                notes.append(f"scenario {name}: condition {nl}={value} dropped (it sets "
                             f"{', '.join(hit)}: the fitted value holds)")
        sc["nonlinearities"] = nls
        sets = sc.get("set")
        if sets:
            flat = dict(dotted_pairs(sets))
            changed = []
            for key, par in FRICTION_OBSERVER.items():
                path = f"controller.{key}"
                if path in flat and par in full:
                    flat[path] = float(full[par])
                    changed.append(f"{key} = {full[par]:.4g}")
            if changed:
                sc["set"] = flat
                notes.append(f"scenario {name}: friction observer set to the fitted friction "
                             f"({', '.join(changed)})")
    return doc, notes


def corners(names: tuple[str, ...], low: Any, high: Any) -> list[tuple[dict[str, float],
                                                                       dict[str, str]]]:
    """The 2^p corners of the box [low, high] -> (values, sides) each, in binary order (the
    first parameter varies slowest)."""
    out = []
    for sides in itertools.product((0, 1), repeat=len(names)):
        vals = {n: float((low, high)[s][j]) for j, (n, s) in enumerate(zip(names, sides,
                                                                            strict=True))}
        out.append((vals, {n: ("low", "high")[s] for n, s in zip(names, sides, strict=True)}))
    return out


FEEDBACK = ("controller.position_feedback", "controller.feedback_blend")
"""Run-config paths that choose the position feedback: a test setting one keeps its own."""


def spec_document(spec_doc: dict[str, Any], plant: dict[str, Any], gains: dict[str, float],
                  name: str | None = None) -> tuple[dict[str, Any], list[str]]:
    """The spec on the fitted actuator with the tuned gains -> (document, notes); ``name``:
    the actuator's (:func:`actuator_name`), which titles the battery's report and figures
    instead of the spec's own actuator.

    The spec's ``actuator:`` becomes ``plant`` + ``gains``. The tuned position-feedback blend
    ``fb_motor`` goes into each test's ``set`` instead, except in a test that chooses its own
    feedback (``controller.position_feedback``, e.g. the free-play test closes the loop on the
    motor angle): there the test's choice holds."""
    from ema_cli.config.loader import dotted_pairs

    doc = copy.deepcopy(spec_doc)
    if name is not None:
        doc["description"] = (f"{name}: the spec {doc.get('name', '')} on the fitted actuator "
                              "with the tuned controller")
        doc["name"] = name
    gains = dict(gains)
    fb = gains.pop("fb_motor", None)
    doc["actuator"] = {"config": None, "plant": {**plant, **gains}, "nonlinearities": {}}
    notes = []
    if fb is not None:
        for name, test in (doc.get("tests") or {}).items():
            flat = dict(dotted_pairs(test.get("set") or {}))
            if any(k in flat for k in FEEDBACK):
                notes.append(f"acceptance test {name}: its own position feedback holds, not "
                             f"the tuned fb_motor = {fb:.4g}")
                continue
            flat["plant.fb_motor"] = fb
            test["set"] = flat
    return doc, notes


@dataclass
class DesignCase:
    """One acceptance run: ``nominal`` (the estimate) or a corner of the 95 % intervals;
    ``values`` the free parameters (SI), ``sides`` low/high per parameter (corners)."""

    name: str
    values: dict[str, float]
    sides: dict[str, str]
    result: AcceptanceResult

    @property
    def passed(self) -> bool:
        return self.result.passed

    @property
    def verdict(self) -> str:
        """The battery's overall verdict: PASS, FAIL or INCONCLUSIVE."""
        return self.result.verdict

    def test_verdicts(self) -> dict[str, bool]:
        """Per test of the spec: whether every limit of it was met."""
        out: dict[str, bool] = {}
        for v in self.result.verdicts:
            out[v.test] = out.get(v.test, True) and bool(v.passed)
        return out

    def test_results(self) -> dict[str, str]:
        """Per test of the spec: PASS, FAIL or INCONCLUSIVE (its rows, as the overall)."""
        from ema_cli.acceptance.verdict import overall

        rows: dict[str, list[str]] = {}
        for v in self.result.verdicts:
            rows.setdefault(v.test, []).append(v.result)
        return {t: overall(r) for t, r in rows.items()}


def design_estimate(plan: dict[str, Any], budget: int | None) -> tuple[float, str]:
    """The estimated time [s] of the whole design and what it counts (announced before the
    identification; the steps' own estimates are not added again): the fit
    (``api.identify_logs.fit_estimate``), the tuning (its evaluations x its scenarios and the
    spec's tests the search measures per candidate) and the nominal sign-off (the battery's
    integration steps); the corners run only while they can change the verdict and are not
    counted."""
    from ema_cli.api.identify_logs import fit_estimate
    from ema_cli.api.tune import tuning_seconds
    from ema_cli.identify.closed_loop.problem import load_log
    from ema_cli.limits import cores
    from ema_cli.progress import duration, kernel_seconds
    from ema_cli.tune.run import evaluations_for
    from ema_cli.tune.spec import SEARCH_KINDS

    ids, tcfg, sp = plan["id_cfg"], plan["tune_cfg"], plan["spec"]
    length = load_log(ids.data, columns=ids.columns, window=ids.window).duration
    fit_s, _ = fit_estimate(ids, length)
    o = tcfg.optimiser
    evals = o.runs * evaluations_for(o.method, budget or o.budget, o.pop, len(tcfg.variables),
                                     o.polish, o.local)
    dt = tcfg.simulation.dt_s
    per_candidate = (len(tcfg.scenarios) * tcfg.simulation.duration_s
                     + sum(t.sim_seconds() for t in sp.tests.values()
                           if t.test in SEARCH_KINDS)) / dt
    battery = sum(t.sim_seconds() for t in sp.tests.values()) / dt
    workers = cores()
    tune_s = tuning_seconds(evals, per_candidate, workers)
    sign_s = kernel_seconds(battery, 1, workers)
    return fit_s + tune_s + sign_s, (
        f"identification {duration(fit_s)}, tuning {duration(tune_s)} ({evals:,} "
        f"evaluations), sign-off {duration(sign_s)} (the nominal case; corners only while "
        "they can change the verdict)")
