"""`ema design LOG`: bad inputs give one-line errors before any work; the whole loop on 1 s of
the bundled independent log (tiny budgets) gives a verdict with every case's battery; an
unconfirmed fit gives INCONCLUSIVE (exit 3) whatever the batteries say."""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest
from typer.testing import CliRunner

from ema_cli.api.design import corners, design_verdict, fitted_tune_document, split_overrides
from ema_cli.cli.main import app
from ema_cli.config.design import EXIT_CODES
from ema_cli.errors import EmaError
from ema_cli.identify.closed_loop.problem import MIN_POSITIVE

ROOT = Path(__file__).resolve().parents[2]
LOG = str(ROOT / "experiments" / "logs" / "design_hc_1pct.csv")
CI_SPEC = str(ROOT / "configs" / "acceptance_geared.yaml")
runner = CliRunner()
# the smallest loop: 1 s of the log, 2 starts, a 2-generation tuning (21: the smallest
# budget whose GA share pays for 8 + 6), the compact spec
TINY = ["--set", "identify.window=[0,1]", "--set", "identify.shooting.starts=2",
        "--set", "tune.optimiser.pop=8", "--budget", "21", "--spec", CI_SPEC]


def invoke(*args: str):
    return runner.invoke(app, ["design", *args], catch_exceptions=False)


def one_clear_line(r, *needles: str) -> None:
    assert r.exit_code == 2, r.output
    lines = [ln for ln in r.output.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("error:"), r.output
    for n in needles:
        assert n in lines[0], r.output


def test_missing_log(tmp_path):
    one_clear_line(invoke(str(tmp_path / "nope.csv")), "nope.csv", "is not a file")
    assert not any(tmp_path.iterdir())


def test_bad_spec_path(tmp_path):
    one_clear_line(invoke(LOG, "--spec", str(tmp_path / "spec.yaml")), "--spec", "spec.yaml",
                   "not a file")


def test_bad_tune_config_path(tmp_path):
    one_clear_line(invoke(LOG, "--tune-config", str(tmp_path / "t.yaml")), "--tune-config")


@pytest.mark.parametrize("setting, needles", [
    ("foo.bar=1", ["--set foo.bar", "identify.KEY=VALUE"]),
    ("identify=3", ["--set identify", "tune.KEY=VALUE"]),
    ("identify.shooting.starts=1", ["identify:", "starts"]),
    ("identify.nonsense=1", ["identify:", "nonsense"]),
    ("tune.optimiser.pop=0", ["tune:", "pop"]),
    ("tune.variables.Kpp.bounds=[5,1]", ["tune:", "Kpp"]),
    ("notanassignment", ["--set", "NAME=VALUE"]),
])
def test_bad_set(tmp_path, setting, needles):
    # every check runs before the identification: the error comes at once, nothing written
    one_clear_line(invoke(LOG, "--set", setting, "--out", str(tmp_path / "o")), *needles)
    assert not (tmp_path / "o").exists()


def test_bad_budget():
    one_clear_line(invoke(LOG, "--budget", "0"), "--budget")


def test_split_overrides_and_corners():
    by = split_overrides([("identify.shooting.starts", "4"), ("tune.optimiser.pop", 8)])
    assert by == {"identify": [("shooting.starts", "4")], "tune": [("optimiser.pop", 8)]}
    with pytest.raises(EmaError, match="identify.KEY=VALUE"):
        split_overrides([("plant.kL", 1)])
    cs = corners(("kL", "alpha"), [1.0, 2.0], [3.0, 4.0])
    # 2^2 corners in binary order, the first parameter slowest
    assert [c[0] for c in cs] == [{"kL": 1.0, "alpha": 2.0}, {"kL": 1.0, "alpha": 4.0},
                                  {"kL": 3.0, "alpha": 2.0}, {"kL": 3.0, "alpha": 4.0}]
    assert cs[1][1] == {"kL": "low", "alpha": "high"}


def test_verdict_rules():
    assert design_verdict([], [True, True]) == "PASS"
    assert design_verdict([], [True, False]) == "FAIL"
    # no PASS on an unconfirmed fit, and no verdict without a case
    assert design_verdict(["not confirmed"], [True, True]) == "INCONCLUSIVE"
    assert design_verdict([], []) == "INCONCLUSIVE"
    # issue 22: an acceptance case INCONCLUSIVE makes the design INCONCLUSIVE (exit 3), a
    # FAIL outranks it
    assert design_verdict([], ["PASS", "INCONCLUSIVE"]) == "INCONCLUSIVE"
    assert design_verdict([], ["INCONCLUSIVE", "FAIL"]) == "FAIL"
    assert design_verdict(["not confirmed"], ["FAIL"]) == "INCONCLUSIVE"
    assert EXIT_CODES == {"PASS": 0, "FAIL": 1, "INCONCLUSIVE": 3}


class _Battery:
    """A stand-in for an acceptance result: only its verdict matters to the corner policy."""

    def __init__(self, verdict):
        self.verdict = verdict
        self.passed = verdict == "PASS"


CASES = [("nominal", {}, {})] + [(f"corner-{k:02d}", {}, {"kL": "low"}) for k in range(1, 5)]


@pytest.mark.parametrize("verdicts, doubts, policy, ran, why", [
    # a FAIL of the nominal case: no corner can turn it back
    (["FAIL"] * 5, [], "auto", 1, "4 interval corners not run: nominal FAILs"),
    # the corners run until one FAILs
    (["PASS", "PASS", "FAIL", "PASS", "PASS"], [], "auto", 3,
     "2 interval corners not run: corner-02 FAILs"),
    # every corner runs while each passes, or is INCONCLUSIVE (a FAIL would still outrank it)
    (["PASS", "INCONCLUSIVE", "PASS", "PASS", "PASS"], [], "auto", 5, ""),
    # a fit that cannot carry a sign-off: INCONCLUSIVE whatever the corners say
    (["PASS"] * 5, ["not confirmed"], "auto", 1, "the fit cannot carry a sign-off"),
    (["FAIL"] * 5, [], "all", 5, ""),
])
def test_corners_run_only_while_they_can_change_the_verdict(monkeypatch, verdicts, doubts,
                                                             policy, ran, why):
    import importlib

    import ema_cli.api.design as d

    acc = importlib.import_module("ema_cli.api.acceptance")  # the module (api/ exports the
    given = iter(verdicts)                                  # function of the same name)
    monkeypatch.setattr(acc, "acceptance", lambda doc: _Battery(next(given)))
    spec = {"name": "s", "tests": {}}
    cases, skipped = d._sign_off(CASES, spec, {}, {}, "log.csv", doubts, policy, [],
                                 lambda _: None)
    assert [c.name for c in cases] == [n for n, _, _ in CASES[:ran]]
    assert why in skipped and bool(skipped) == bool(why)
    # the verdict the cases run give is the one all cases would give
    assert d.design_verdict(doubts, [c.verdict for c in cases]) == d.design_verdict(
        doubts, verdicts if not doubts else verdicts[:1])


def test_repeated_outcomes_are_named_once():
    from ema_cli.api.design import actuator_name, case_list

    corners_ = [f"corner-{k:02d}" for k in range(1, 17)]
    assert case_list(["nominal", *corners_], 17) == "all 17 cases"
    assert case_list(["nominal", *corners_[:5]], 17) == "nominal and 5 corners"
    assert case_list(corners_[:2], 17) == "corner-01, corner-02"
    assert case_list(["nominal"], 1) == "nominal"
    # the fitted actuator titles the figures by the log's name, a folder-safe one
    assert actuator_name("experiments/logs/design_hc_1pct.csv") == "design_hc_1pct-fitted"
    assert actuator_name("a b(1).csv", "corner-03") == "a-b-1-fitted-corner-03"


def test_tune_document_on_the_fitted_actuator():
    from ema_cli.config.loader import read_yaml

    doc = read_yaml(ROOT / "configs" / "tune.yaml")
    plant = {"kL": 500.0, "alpha": 0.002, "Fc": 0.03, "sigma2": 0.02, "friction": 1}
    full = {"Fc": 0.03, "Fs": 0.045, "vs": 1.0, "sigma2": 0.02, "sigma0": 30.0, "sigma1": 0.03}
    out, notes = fitted_tune_document(doc, plant, full)
    assert out["actuator"]["plant"] == plant
    # deadzone2 sets alpha, friction1 sets sigma2: both identified, so dropped
    assert out["scenarios"]["deadband"]["nonlinearities"] == {}
    assert out["scenarios"]["friction"]["nonlinearities"] == {}
    # the amplifier dead zone is not identified: the scenario keeps it
    assert out["scenarios"]["deadzone"]["nonlinearities"] == {"deadzone1": 1.0}
    ff = out["scenarios"]["friction"]["set"]
    assert ff["controller.friction_ff_fc_nm"] == 0.03
    assert ff["controller.friction_ff_fs_nm"] == 0.045
    assert ff["controller.friction_ff_sigma0"] == 30.0
    assert len(notes) == 3


@pytest.mark.slow
def test_end_to_end_tiny_and_inconclusive(tmp_path, monkeypatch):
    """The whole loop with tiny budgets; the fit's doubts are forced to include one, so the
    verdict must be INCONCLUSIVE (exit 3) whatever the 17 batteries say."""
    import ema_cli.api.design as d

    real = d.fit_doubts
    monkeypatch.setattr(d, "fit_doubts", lambda fit: [
        *real(fit), "the identification's optimum is not confirmed: forced by the test"])
    out = tmp_path / "d"
    r = runner.invoke(app, ["design", LOG, *TINY, "--corners", "all", "--out", str(out)],
                      catch_exceptions=False)
    assert r.exit_code == 3, r.output
    js = json.loads((out / "design.json").read_text())
    assert js["verdict"] == "INCONCLUSIVE" and js["exit_code"] == 3
    assert any("forced by the test" in why for why in js["inconclusive_because"])
    ident = js["identification"]["parameters"]
    # the contact law unstated: zeta_t, contact_tau and the Hunt-Crossley share contact_hc
    # free nuisance parameters, not corners
    assert list(ident) == ["kL", "alpha", "Fc", "sigma2", "zeta_t", "contact_tau", "contact_hc"]
    cases = js["acceptance"]["cases"]
    assert all(set(c["sides"]) <= {"kL", "alpha", "Fc", "sigma2"} for c in cases)
    assert all(c["parameters"]["zeta_t"] == cases[0]["parameters"]["zeta_t"] for c in cases)
    assert len(cases) == 1 + 2**4
    assert cases[0]["case"] == "nominal" and cases[0]["sides"] == {}
    assert len(cases[0]["tests"]) == 6  # configs/acceptance_geared.yaml
    # every corner is a distinct combination of interval ends (clipped to the bounds)
    assert len({tuple(sorted(c["sides"].items())) for c in cases[1:]}) == 16
    free = json.loads((out / "identification" / "identification.json").read_text())["free"]
    for c in cases[1:]:
        for n, side in c["sides"].items():
            lo, hi = ident[n]["ci95"]
            # (and to the positive floor of the parameters that must stay positive)
            want = (max(lo, free[n][0], MIN_POSITIVE.get(n, -math.inf)) if side == "low"
                    else min(hi, free[n][1]))
            assert c["parameters"][n] == pytest.approx(want, rel=1e-12, abs=1e-12)
    assert set(js["tuning"]["gains_after"]) == {"Kpp", "Kps", "Kis", "fb_motor"}
    for sub in ("identification/fitted.yaml", "tune/tuned.yaml",
                "acceptance/nominal/acceptance.csv", "acceptance/corner-16/acceptance.md",
                "design.md", "manifest.json"):
        assert (out / sub).is_file(), sub
    md = (out / "design.md").read_text()
    assert md.splitlines()[2].startswith("**Verdict: INCONCLUSIVE**")
    assert "INCONCLUSIVE" in r.output
    # the report (from the verdict line on) fits 80 columns; progress lines come before it
    tail = r.output[r.output.index("INCONCLUSIVE: ema design"):]
    assert all(len(ln) <= 80 for ln in tail.splitlines()), tail


@pytest.mark.slow
def test_the_readme_design_line_ends_in_an_answer(tmp_path, monkeypatch):
    """README's Use section: `ema design experiments/logs/design_hc_1pct.csv`, defaults. It
    must end PASS, or FAIL naming the requirement no gains inside the bounds meet with the
    best value reached. The bundled spec's load deflection (motor locked, +-20 N*m) <= 0.05
    deg cannot hold on this log's actuator: the lost motion alone, twice the identified half
    backlash alpha (2.5 mrad: 0.286 deg, independent of any controller), exceeds it."""
    monkeypatch.chdir(ROOT)  # the README's relative path
    out = tmp_path / "d"
    r = runner.invoke(app, ["design", "experiments/logs/design_hc_1pct.csv", "--out",
                            str(out)], catch_exceptions=False)
    assert r.exit_code in (0, 1), r.output
    js = json.loads((out / "design.json").read_text())
    if js["verdict"] == "PASS":
        return
    alpha = js["identification"]["parameters"]["alpha"]["value"]
    assert math.degrees(2 * alpha) > 0.05  # the closed form: the spec's limit cannot hold
    unmet = {row["requirement"]: row for row in js["requirements"]["unmet"]}
    ld = unmet["load-deflection: free_play"]
    assert ld["blocking"] and ld["tier"] == "fixed"
    value_deg = float(ld["value"].split()[0])
    assert value_deg >= math.degrees(2 * alpha) * 0.99  # at least the gap (1 % slack)
    # the answer is the console's last words before the closing line, and design.md's first
    text = " ".join(r.output.split())
    assert ("no gains can meet load-deflection: free_play <= 0.05 deg "
            f"({ld['reached']} whatever the gains)") in text
    assert "no PASS without relaxing these limits" in text
    assert text.index("no gains can meet") > text.index("interval corners not run")
    md = (out / "design.md").read_text()
    assert "**No gains can meet load-deflection: free_play" in md
    assert str(ROOT) not in md and "/tmp" not in md  # no machine path
    # no corner ran after the nominal FAIL, and the reason is said once
    assert js["acceptance"]["corners"]["run"] == 0
    assert r.output.count("interval corners not run") == 1
