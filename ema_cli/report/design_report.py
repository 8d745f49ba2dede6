"""The run folder of ``ema design``: design.json, design.md (the verdict first) and the manifest;
the three steps' folders are written by their own results (the caller prepares the folder)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from ema_cli.report.markdown import md_cell
from ema_cli.report.rundir import manifest, write_json, write_text

VERDICT_MEANING = {
    "PASS": "the tuned controller meets every limit of the spec on the fitted actuator and on "
            "every corner of the identified 95 % intervals",
    "FAIL": "at least one case (the fitted actuator or an interval corner) misses a limit",
    "INCONCLUSIVE": "the identification cannot carry a sign-off, whatever the batteries say",
}


def design_markdown(js: dict[str, Any]) -> str:
    """design.md from the content of design.json: the answer first, then the identified
    actuator, the tuned gains, the acceptance table (cases x tests)."""
    v = js["verdict"]
    lines = [f"# ema design: {js['log']}", "", f"**Verdict: {v}** (exit code {js['exit_code']}):"
             f" {VERDICT_MEANING[v]}."]
    for why in js["inconclusive_because"]:
        lines.append(f"- {why}")
    acc = js["acceptance"]
    cases = acc["cases"]
    n_pass = sum(c["passed"] for c in cases)
    lines += ["", f"Acceptance ({acc['spec']}): {n_pass} of {len(cases)} cases pass "
              f"(the fitted actuator and {len(cases) - 1} interval corners)."]
    ident = js["identification"]
    lines += ["", "## Identified actuator", "",
              "| parameter | value | 95 % interval | unit | determined | truth |",
              "|---|---:|---|---|---|---:|"]
    truth = ident.get("truth") or {}
    for n, p in ident["parameters"].items():
        lo, hi = p["ci95"]
        t = md_cell(truth[n], 5) if n in truth else "-"
        lines.append(f"| {n} | {md_cell(p['value'], 5)} | [{md_cell(lo, 5)}, "
                     f"{md_cell(hi, 5)}] | {p['unit']} | "
                     f"{'yes' if p['determined'] else 'NO'} | {t} |")
    opt = ident["optimum"]
    lines += ["", "Optimum: " + ("not checked (GA search)" if opt is None else
                                 "confirmed" if opt["confirmed"] else
                                 "NOT confirmed: " + "; ".join(opt["not_confirmed_because"]))
              + ". Details: identification/summary.md; the fitted run config: "
              "identification/fitted.yaml."]
    tr = js["tuning"]
    lines += ["", "## Tuned controller", "",
              f"{tr['method']}, {tr['evaluations']} evaluations ({tr['config']}, on the fitted "
              "actuator). Cost: " + tr["cost_meaning"] + ".", "",
              "| gain | before | after |", "|---|---:|---:|"]
    for g, after in tr["gains_after"].items():
        lines.append(f"| {g} | {md_cell(tr['gains_before'][g], 5)} | {md_cell(after, 5)} |")
    lines.append(f"| cost | {md_cell(tr['cost_before'], 5)} | {md_cell(tr['cost_after'], 5)} |")
    lines += ["", "Details: tune/tuning.md; the tuned actuator: tune/tuned.yaml.", "",
              "## Acceptance: cases x tests", ""]
    names = list(ident["parameters"])
    head = ["case", *names, *acc["tests"], "verdict"]
    lines += ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for c in cases:
        vals = [md_cell(c["parameters"][n], 5) + ({"low": " (lo)", "high": " (hi)"}.get(
            c["sides"].get(n, ""), "")) for n in names]
        md = {"PASS": "pass", "FAIL": "**FAIL**", "INCONCLUSIVE": "_inconclusive_"}
        tests = [md[c["test_results"].get(t, "FAIL")] for t in acc["tests"]]
        lines.append("| " + " | ".join([c["case"], *vals, *tests,
                                        md[c["verdict"]].upper()]) + " |")
    failed = [(c["case"], f) for c in cases for f in c["failed_limits"]]
    if failed:
        lines += ["", "Limits not met (value in the limit's unit; each case's acceptance.md "
                      "gives the limits):", ""]
        lines += [f"- {case}: {f}" for case, f in failed[:40]]
        if len(failed) > 40:
            lines.append(f"- ... {len(failed) - 40} more (design.json)")
    if js["notes"]:
        lines += ["", "## Notes", ""] + [f"- {n}" for n in js["notes"]]
    t = js["timings_s"]
    lines += ["", "Wall time: " + ", ".join(f"{k} {v:.1f} s" for k, v in t.items()) + ".", ""]
    return "\n".join(lines)


def write_design(folder: Path, result: Any) -> list[str]:
    """Write design.json, design.md and manifest.json into ``folder`` -> the names written."""
    js = result.to_json()
    write_json(folder / "design.json", js)
    write_text(folder / "design.md", design_markdown(js))
    names = ["design.json", "design.md", "identification/", "tune/", "acceptance/",
             "manifest.json"]
    write_json(folder / "manifest.json", manifest(
        "design", outputs=names, log=js["log"], verdict=js["verdict"],
        tune_config=result.tune_source, spec=result.spec_source,
        config=result.config.model_dump(mode="json"),
        overrides=[[k, v] for k, v in result.overrides], wall_time_s=js["timings_s"],
        execution=result.execution))
    return names
