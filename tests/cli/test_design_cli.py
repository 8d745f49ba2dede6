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
# the smallest loop: 1 s of the log, 2 starts, a 2-generation tuning, two cheap tests
TINY = ["--set", "identify.window=[0,1]", "--set", "identify.shooting.starts=2",
        "--set", "tune.optimiser.pop=8", "--budget", "16", "--spec", CI_SPEC]


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
    r = runner.invoke(app, ["design", LOG, *TINY, "--out", str(out)], catch_exceptions=False)
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
