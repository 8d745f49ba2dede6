"""One vocabulary (issue 39, item 5): the same gain margin, settling time and not-measured value
read the same in ``margins``, ``acceptance`` (console and acceptance.md), ``yield.md``,
``design.md`` (design.json's failed limits) and the API's tables."""

from __future__ import annotations

import math
from pathlib import Path

import pandas as pd
import pytest

from ema_cli import vocab
from ema_cli.acceptance.verdict import Verdict


def _verdict(metric: str, unit: str, value: float, measured: bool, lower: float,
             upper: float, note: str = "", result: str = "PASS") -> Verdict:
    return Verdict(test="speed", kind="margins", metric=metric, condition="speed loop",
                   value=value, min=6.0, max=None, unit=unit, result=result,
                   measured=measured, lower=lower, upper=upper, value_si=value, si_unit=unit,
                   note=note, reason="")


# the speed loop's gain margin with no phase crossover in the simulated band: a lower bound
NO_PHASE = _verdict("gain_margin", "dB", 109.4, False, 109.4, math.inf,
                    note="no phase crossover up to 200 Hz")
NOT_MEASURED = _verdict("rise_time", "s", math.nan, False, math.nan, math.nan,
                        result="INCONCLUSIVE")


def _every_command(v: Verdict) -> dict[str, str]:
    """The text each command prints for verdict ``v``."""
    from ema_cli.api.acceptance import AcceptanceResult
    from ema_cli.cli.acceptance import _value
    from ema_cli.report.acceptance_report import fmt_measured
    from ema_cli.report.yield_report import measured_cells
    from ema_cli.vocab import verdict_text as _shown

    res = AcceptanceResult.__new__(AcceptanceResult)
    res.verdicts = [v]
    samples = pd.DataFrame({f"l [{v.unit}]": [v.value] * 3, "l measured": [v.measured] * 3,
                            "l lower": [v.lower] * 3})
    return {"acceptance console": _value(v, None),
            "acceptance.md (unit in its own column)": fmt_measured(v, with_unit=False),
            "design.json/design.md": res.failed_limits()[0].split(") ", 1)[1]
            if v.result == "FAIL" else _shown(v),
            "API to_pandas reads": res.to_pandas()["reads"].iloc[0],
            "yield.md median": measured_cells(samples, "l", v.unit, v.metric)[0]}


def test_a_gain_margin_without_phase_crossover_reads_the_same_everywhere():
    from ema_cli.cli.margins import margins_cells
    from ema_cli.report.margins_report import margin_text

    shown = _every_command(NO_PHASE)
    want = "no phase crossover (> 109.4 dB)"
    assert shown.pop("acceptance.md (unit in its own column)") == "no phase crossover (> 109.4)"
    assert set(shown.values()) == {want}, shown
    # the linear model's margin (margins): infinite, the same words without a bound

    class M:
        gm_db, f_gm_hz, pm_deg, f_pm_hz = math.inf, math.nan, 45.0, 12.0

    gm, _, pm, _ = margins_cells(M)
    assert gm == "no phase crossover" == margin_text(math.nan, "gain_margin")
    assert want.startswith(gm)
    assert pm == "45 deg"


def test_not_measured_reads_the_same_everywhere():
    shown = _every_command(NOT_MEASURED)
    assert set(shown.values()) == {"not measured"}, shown


def test_a_measured_value_and_the_words():
    v = _verdict("settling_time", "s", 0.1234567, True, 0.1234567, 0.1234567)
    shown = _every_command(v)
    assert shown.pop("acceptance.md (unit in its own column)") == "0.1235"
    assert set(shown.values()) == {"0.1235 s"}, shown
    assert vocab.bound(2.0, math.inf, "Hz") == "> 2 Hz"
    assert vocab.bound(0.0, 1e-4, "s") == "<= 0.0001 s"
    assert vocab.bound(1.0, 2.0, "s") == "1..2 s"
    assert vocab.number(math.inf, "dB") == "∞ dB"
    assert vocab.not_settled(1.0) == "not settled within 1 s"
    assert vocab.free_play(0.02) == "0.02 deg"
    assert vocab.free_play(-0.01).startswith("-0.01 deg (negative: ")


def test_a_bound_is_never_a_median_in_yield_md():
    # some units measured, some only bounded: the median is over the measured ones, the
    # others counted apart (a bound is not a measurement)
    from ema_cli.report.yield_report import measured_cells

    samples = pd.DataFrame({"l [dB]": [20.0, 30.0, 109.4], "l measured": [True, True, False],
                            "l lower": [20.0, 30.0, 109.4]})
    median, spread = measured_cells(samples, "l", "dB", "gain_margin")
    assert median == "25 dB (1 units: a bound only)"
    assert spread == "20 to 30 dB"


@pytest.mark.parametrize("value", [math.inf, math.nan])
def test_margins_words_for_no_crossover(value):
    from ema_cli.vocab import margin_text

    assert margin_text(value, "phase_margin") == "no gain crossover"


def test_paths_in_output_are_never_absolute(tmp_path, monkeypatch):
    # reproduce printed absolute and ../ paths: output shows a path relative to the working
    # folder when inside it, else its last two parts
    from ema_cli.files import shown

    (tmp_path / "configs").mkdir()
    cfg = tmp_path / "configs" / "a.yaml"
    monkeypatch.chdir(tmp_path)
    assert shown(cfg) == "configs/a.yaml"
    assert shown(tmp_path / "experiments" / ".." / "configs" / "a.yaml") == "configs/a.yaml"
    monkeypatch.chdir(tmp_path / "configs")
    assert shown(Path("../configs/a.yaml")) == "a.yaml"
    outside = Path("/somewhere/else/deep/b.yaml")
    assert shown(outside) == "deep/b.yaml"
