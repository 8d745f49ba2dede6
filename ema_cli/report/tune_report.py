"""Files and figures of ``ema tune``: tuned.yaml, scenario configs, CSVs, figures, tuning.md."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.figure import Figure

from ema_cli.report.figures import subplots
from ema_cli.report.markdown import md_table
from ema_cli.report.rundir import manifest, write_csv, write_figure, write_json, write_text
from ema_cli.units import DEG

OUTPUT_FILES = ("tuned.yaml", "tuning.csv", "runs.csv", "scenarios.csv", "constraints.csv",
                "convergence.png", "tuning.md", "config.resolved.yaml", "manifest.json")
LABELS = {"reference": "default controller", "before": "before tuning (compensators on)",
          "after": "tuned"}
STYLES = {"reference": ("0.55", "-"), "before": ("C0", "--"), "after": ("C3", "-")}


def convergence_figure(res: Any) -> Figure:
    """Best cost so far vs candidate evaluations, one line per run (infeasible: not drawn),
    with the default controller's cost (1) and the start's."""
    from ema_cli.tune.problem import INFEASIBLE

    fig, ax = subplots(1, 1, figsize=(9, 5.5))
    for k, r in enumerate(res.outcome.runs):
        h = r.result.history
        ever = np.asarray(h.best_ever, dtype=float)
        y = np.where(ever < INFEASIBLE, ever, np.nan)
        ax.plot(h.evaluations, y, "-", lw=1.2, color=f"C{k % 10}",
                label=f"seed {r.seed}: {r.cost:.4g}" if k < 12 else None)
    before = float(res.outcome.before.cost[0])
    if res.config.cost.normalise:
        ax.axhline(1.0, color="0.4", ls=":", lw=1.0, label="default controller (1)")
    if math.isfinite(before):
        ax.axhline(before, color="C0", ls="--", lw=1.0,
                   label=f"before tuning: {before:.4g}")
    ax.set_xlabel("candidate evaluations (each runs every scenario)")
    what = ("mean ITAE ratio" if res.config.cost.metric == "itae" else
            f"{res.config.cost.aggregate} {res.config.cost.metric.upper()}")
    norm = " (1 = default controller)" if res.config.cost.normalise else ""
    ax.set_ylabel(f"best feasible cost: {what}{norm} [-]")
    ax.set_yscale("log")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8, loc="upper right")
    ax.set_title(f"{res.title}: convergence of {len(res.outcome.runs)} run(s), "
                 f"{res.outcome.runs[0].result.evaluations} evaluations each")
    fig.subplots_adjust(left=0.1, right=0.97, bottom=0.1, top=0.92)
    return fig


COINCIDE_DEG = 1e-6  # error curves closer than this everywhere are said to coincide [deg]


def scenario_figure(res: Any, s: int) -> Figure:
    """Load angle and position error of scenario ``s`` for the default, the start and the
    tuned controllers (degrees, seconds)."""
    sc = res.outcome.problem.scenarios[s]
    from ema_cli.report.figures import coincidence_note, coinciding

    fig, axes = subplots(2, 1, figsize=(10, 8), sharex=True)
    ref_drawn = False
    errors: dict[str, Any] = {}
    for which in ("reference", "before", "after"):
        ev = res.evaluation(which)
        b = ev.batch
        if b is None:
            continue
        t = b.t_out
        th = b.signal("theta_load", s) / DEG
        err = b.signal("err_pos", s) / DEG
        if not ref_drawn:
            axes[0].plot(t, b.signal("theta_ref", s) / DEG, color="k", lw=0.9, ls=":",
                         label="reference")
            ref_drawn = True
        color, ls = STYLES[which]
        lab = f"{LABELS[which]} (ratio {float(ev.ratio[0, s]):.3g})"
        axes[0].plot(t, th, color=color, ls=ls, lw=1.3, label=lab)
        axes[1].plot(t, err, color=color, ls=ls, lw=1.3, label=LABELS[which])
        errors[LABELS[which]] = err
    axes[0].set_ylabel("load angle theta_L [deg]")
    axes[1].set_ylabel("position error theta_ref - theta_L [deg]")
    axes[1].set_xlabel("time [s]")
    axes[0].legend(fontsize=8, loc="lower right")
    axes[1].axhline(0.0, color="0.5", lw=0.7)
    metric = res.config.cost.metric.upper()
    axes[0].set_title(f"Scenario {sc.name}: response ({metric} ratio to the default "
                      "controller in brackets)")
    # a curve drawn under another is said (as freqresp's Bode plot does)
    note = coincidence_note(coinciding(errors, COINCIDE_DEG), COINCIDE_DEG, "deg")
    axes[1].set_title("Position error" + (f"\ncurves on each other: {note}" if note else ""))
    for a in axes:
        a.grid(True, alpha=0.3)
    fig.suptitle(res.title)
    fig.subplots_adjust(left=0.1, right=0.97, bottom=0.07, top=0.9, hspace=0.25)
    return fig


def tuning_markdown(res: Any, figures: list[str]) -> str:
    """tuning.md: the verdict, the tuned values, the cost before and after, every constraint's
    value and limit, the runs, and the figures."""
    o = res.outcome
    cfg = res.config
    after = float(o.after.cost[0])
    before = float(o.before.cost[0])
    lines = [f"# {res.title}", "",
             f"Config: `{res.source}`. Method: {o.method_label}, {len(o.runs)} run(s) of "
             f"{o.runs[0].result.evaluations} candidate evaluations, each running all "
             f"{len(o.problem.scenarios)} scenarios ({cfg.simulation.duration_s:g} s, step "
             f"{cfg.simulation.dt_s:g} s) in one batched kernel call per generation. "
             f"Wall time {o.wall_s:.1f} s (kernel {o.timings['kernel_s']:.1f} s, margins "
             f"{o.timings['margins_s']:.1f} s).", ""]
    what = (f"{cfg.cost.aggregate} over the scenarios of each scenario's "
            f"{cfg.cost.metric.upper()}" + (" divided by its value with the default controller"
                                            if cfg.cost.normalise else ""))
    lines += ["## Result", "",
              f"- Cost ({what}): default controller "
              f"{float(o.reference.cost[0]):.4g}, before tuning {before:.4g}, "
              f"**tuned {after:.4g}**"
              + (f" ({100 * (1 - after / float(o.reference.cost[0])):.1f} % below the default "
                 "controller)." if math.isfinite(after) else "."),
              f"- Every constraint met: {'yes' if o.feasible else 'NO'} (feasibility first: "
              "a feasible candidate always beats an infeasible one).",
              f"- Step check: the tuned cost on half the step ({o.check_dt:g} s) is "
              f"{o.check_cost:.4g}, {100 * (o.check_cost / after - 1):+.2f} % from "
              f"{after:.4g}.",
              f"- Runs: costs from {min(r.cost for r in o.runs):.4g} to "
              f"{max(r.cost for r in o.runs):.4g} (spread {100 * o.cost_spread:.2f} %).", "",
              "## Tuned values (SI, `ema params` names)", "",
              "| variable | before | tuned | bounds | scale |", "|---|---|---|---|---|"]
    for v, x in res.tuned.items():
        spec = cfg.variables[v]
        lines.append(f"| {v} | {res.initial[v]:.6g} | {x:.6g} | "
                     f"[{spec.bounds[0]:g}, {spec.bounds[1]:g}] | {spec.scale} |")
    lines += bounds_markdown(res)
    lines += ["", "`tuned.yaml` is the actuator with these values (`ema simulate tuned.yaml`); "
              "`scenarios/NAME.yaml` (tuned), `scenarios/NAME.before.yaml` and "
              "`scenarios/NAME.default.yaml` are each scenario with the three controllers, "
              "every one runnable with `ema simulate`.", "",
              "## Scenarios", "", md_table(res.scenarios_frame()), "",
              "## Constraints (value of each controller in the limit's unit)", "",
              md_table(res.constraints_frame()), "",
              "Always: no scenario may diverge and the closed linear loop must be stable. "
              "Margins are those of the linearised loops (position and speed, the smaller).",
              "", "## Runs", "", md_table(res.runs_frame()), ""]
    lines += spec_markdown(res)
    lines += ["## Figures", ""]
    lines += [f"![{f}]({f})" for f in figures]
    return "\n".join(lines) + "\n"


def bounds_markdown(res: Any) -> list[str]:
    """The tuned variables on (within 1 % of) a bound, one item each (none: nothing)."""
    flags = res.on_bounds()
    if not flags:
        return []
    return ["", "**On a bound** (within 1 % of the range, on the variable's scale):", ""] + [
        f"- {f['text']}" for f in flags]


def spec_markdown(res: Any) -> list[str]:
    """The spec's section of tuning.md: its requirements, how the search saw them, the
    battery's verdict on the tuned controller and on the checked candidates (none without a
    spec)."""
    o = res.outcome
    sp = o.spec
    if sp is None:
        return []
    margin = 100 * sp.margin
    pick = o.checked[o.chosen]
    lines = ["## Requirements of the spec", "",
             f"Spec `{sp.source}` ({len(sp.spec.tests)} tests) with the tuned controller: "
             f"**{pick['verdict']}** by the battery (`ema acceptance`'s own code)."
             + (f" **{res.unmeetable()[0].upper()}{res.unmeetable()[1:]}.**"
                if res.unmeetable() else ""), "",
             f"- In the search (tier `search`), each requirement's limit is tightened by "
             f"{margin:g} % of its value (the search's min/max columns); the sign-off uses the "
             "spec's own. Tier `fixed`: the controller plays no part (motor locked), measured "
             "once. Tier `check`: measured by the whole battery on the "
             f"{len(o.checked)} best distinct controllers of the search after it; the tuned "
             f"controller is the best of them by the battery's numbers"
             + (f" (checked controller {1 + o.chosen}: the battery ranked the search's own "
                "best lower)" if o.chosen else " (the search's own best)") + ".",
             f"- Screening: {sp.screened} controllers across the bounds (the start and "
             "Sobol points) measured the search tier before the search."]
    if sp.unreachable:
        lines.append("- Out of the controller's reach (left the search's constraints): "
                     + "; ".join(f"{k} {why}" for k, why in sp.unreachable.items()) + ".")
    agree = [sum(c["search_met"][r.key] == (c["readings"][r.key][3] == 0.0)
                 for c in o.checked) for r in sp.by_tier("search")]
    if agree:
        lines.append(f"- The search's measurements (the battery's code, the threshold's proxy) "
                     f"agreed with the battery on met/not met for {sum(agree)} of "
                     f"{len(agree) * len(o.checked)} (requirement, checked controller) pairs.")
    lines += ["", md_table(res.requirements_frame()), "",
              "Checked controllers (search's best first): " + ", ".join(
                  f"{k + 1}: {c['verdict']} (cost {c['cost']:.4g})"
                  for k, c in enumerate(o.checked)) + ".", ""]
    return lines


def write_tuning(folder: Path, config_yaml: str, res: Any) -> None:
    """Every output of a tuning into ``folder`` (atomic writes)."""
    import yaml

    def dump(doc: Any) -> str:
        return yaml.safe_dump(doc, sort_keys=False)

    write_text(folder / "config.resolved.yaml", config_yaml)
    write_text(folder / "tuned.yaml", "# ema tune: the actuator with the tuned controller "
               "(ema simulate tuned.yaml)\n" + dump(res.tuned_document()))
    (folder / "scenarios").mkdir(exist_ok=True)
    for sc in res.outcome.problem.scenarios:
        for which, suffix in (("after", ""), ("before", ".before"), ("reference", ".default")):
            write_text(folder / "scenarios" / f"{sc.name}{suffix}.yaml",
                       dump(res.scenario_document(sc.name, which)))
    write_csv(folder / "tuning.csv", res.history(), float_format="%.9g")
    write_csv(folder / "runs.csv", res.runs_frame(), float_format="%.9g")
    write_csv(folder / "scenarios.csv", res.scenarios_frame(), float_format="%.9g")
    write_csv(folder / "constraints.csv", res.constraints_frame(), float_format="%.9g")
    if res.outcome.spec is not None:
        write_csv(folder / "requirements.csv", res.requirements_frame(), float_format="%.9g")
    write_figure(folder / "convergence.png", convergence_figure(res))
    figures = ["convergence.png"]
    for s, sc in enumerate(res.outcome.problem.scenarios):
        name = f"scenario_{sc.name}.png"
        write_figure(folder / name, scenario_figure(res, s))
        figures.append(name)
    write_text(folder / "tuning.md", tuning_markdown(res, figures))
    o = res.outcome
    write_json(folder / "manifest.json", manifest(
        "tune", outputs=list(OUTPUT_FILES) + figures[1:], method=o.method,
        seeds=[r.seed for r in o.runs], budget=o.runs[0].result.evaluations,
        cost=float(o.after.cost[0]), feasible=o.feasible, tuned=res.tuned,
        verdict=res.verdict, on_bounds=[f["variable"] for f in res.on_bounds()],
        wall_time_s=o.wall_s, timings=o.timings, source=res.source,
        overrides=[[k, v] for k, v in res.overrides], execution=res.execution))
