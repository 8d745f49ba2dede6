"""model/params.py: the parameter table, value checks, derived values, and docs/model.md §4."""

from __future__ import annotations

import math
import re
from pathlib import Path

import pytest

from ema_cli.errors import EmaError
from ema_cli.model.params import (
    BY_NAME,
    FLAGS,
    INDEX,
    N_PARAMS,
    PARAMS,
    check_value,
    equivalent_inertia,
    resolve,
    to_row,
)

MODEL_MD = Path(__file__).resolve().parents[2] / "docs" / "model.md"
DERIVED = {"c", "sigma_t", "Fs", "sigma0", "sigma1", "Fc_neg", "Fs_neg", "sigma2_neg", "Fs_L",
           "Fc_L_neg",
           "Fs_L_neg", "Fv_L_neg", "sigma0_L", "sigma1_L"}
NEGATIVE_OK = {"T_load", "k_h", "offset", *(f"dc_fir{k}" for k in range(8)),
               *(f"x0_{s}" for s in ("theta_m", "w_m", "i", "theta_L", "w_L", "z", "xI", "f_amp",
                                     "z_L", "f_t", "th_w", "th_h"))}
# docs/model.md §4: only these may be negative (loads, the offset, FIR taps, initial states)


def doc_table(heading: str) -> list[list[str]]:
    """The rows (cells stripped) of the first markdown table under ``heading``."""
    text = MODEL_MD.read_text(encoding="utf-8")
    start = text.index(heading)
    rows = []
    for line in text[start:].splitlines()[1:]:
        if line.startswith("## "):
            break
        if line.startswith("|") and not line.startswith("|---"):
            rows.append([c.strip() for c in line.strip().strip("|").split("|")])
        elif rows and not line.startswith("|"):
            break  # the table ended
    return rows[1:]  # drop the header


def first_number(cell: str) -> float:
    m = re.search(r"[-+]?\d+(?:\.\d+)?(?:[eE][-+]?\d+)?", cell)
    assert m, cell
    return float(m.group())


def doc_unit(cell: str) -> str:
    return cell.replace("·", "*").replace("²", "^2")


DOC_ROWS = doc_table("## 4. Default parameters")


# ------------------------------------------------------------------------------------------
# the table


def test_table_names_unique_and_index_round_trip():
    names = [p.name for p in PARAMS]
    assert len(names) == len(set(names)) == N_PARAMS == len(INDEX) == len(BY_NAME)
    for i, p in enumerate(PARAMS):
        assert INDEX[p.name] == i and PARAMS[INDEX[p.name]] is p and BY_NAME[p.name] is p
    assert list(INDEX.values()) == list(range(N_PARAMS))


def test_defaults_finite_or_derived():
    for p in PARAMS:
        if p.name in DERIVED:
            assert p.default is None, p.name
        else:
            assert isinstance(p.default, float), p.name
            assert math.isfinite(p.default) or p.limit, p.name  # a limit may default to none
        assert p.unit and p.description, p.name
        assert p.nonnegative == (p.name not in NEGATIVE_OK), p.name
    assert set(FLAGS) <= set(INDEX)


def test_to_row_is_table_order():
    values = resolve()
    row = to_row(values)
    assert len(row) == N_PARAMS
    assert all(isinstance(x, float) and (math.isfinite(x) or PARAMS[k].limit)
               for k, x in enumerate(row))
    for p in PARAMS:
        assert row[INDEX[p.name]] == values[p.name]
    assert set(values) == set(INDEX)


# ------------------------------------------------------------------------------------------
# docs/model.md §4


def test_doc_table_lists_every_parameter_in_order_with_its_unit():
    assert [r[0].strip("`") for r in DOC_ROWS] == [p.name for p in PARAMS]
    for r in DOC_ROWS:
        assert doc_unit(r[2]) == BY_NAME[r[0].strip("`")].unit, r


def test_doc_defaults_match_resolved_defaults():
    values = resolve()
    for r in DOC_ROWS:
        name = r[0].strip("`")
        if r[1].startswith("inf"):  # "inf (none)": a limit that is off by default
            assert values[name] == math.inf, name
            continue
        doc = first_number(r[1])  # "0.77328 (derived)", "13.963 (= 800 °/s)", "`contact` (0)"
        # the doc prints 5 significant digits at most
        assert values[name] == pytest.approx(doc, rel=5e-5, abs=1e-12), (name, r[1])


def test_key_defaults_hard_coded():
    # docs/model.md §4; derived values computed by hand:
    # Jm*m^2 = 3e-5*576 = 0.01728, Jeq = 0.01728*0.01/0.02728 = 6.33431e-3 kg*m^2
    # c = 2*0.2*sqrt(590*6.33431e-3) = 0.77328; sigma1 = sqrt(20*3e-5) = 0.0244949
    v = resolve()
    assert v["kL"] == 590.0 and v["m"] == 24.0 and v["Kpp"] == 50.0
    assert v["sat1"] == pytest.approx(800 * math.pi / 180, rel=1e-15)
    assert v["sat3"] == pytest.approx(30.35, rel=1e-15)
    assert equivalent_inertia(v) == pytest.approx(6.33431e-3, rel=1e-5)
    assert v["c"] == pytest.approx(0.77328, rel=1e-5)
    assert v["Fs"] == pytest.approx(0.03, rel=1e-15)
    assert v["sigma0"] == pytest.approx(20.0, rel=1e-15)
    assert v["sigma1"] == pytest.approx(0.0244949, rel=1e-6)
    assert v["damping"] == 0.0 and v["friction"] == 0.0 and v["locked"] == 0.0


# ------------------------------------------------------------------------------------------
# resolve: overrides and derived values


def test_overrides_land_in_the_row():
    v = resolve({"Kpp": 60, "alpha": "0.002", "sat2": "off", "friction": "on", "damping": "paper",
                 "T_load": -3.5})
    row = to_row(v)
    assert row[INDEX["Kpp"]] == 60.0 and row[INDEX["alpha"]] == 0.002
    assert row[INDEX["sat2"]] == math.inf and row[INDEX["friction"]] == 1.0
    assert row[INDEX["damping"]] == 1.0 and row[INDEX["T_load"]] == -3.5
    # the rest stays at the defaults
    d = resolve()
    for name in set(INDEX) - {"Kpp", "alpha", "sat2", "friction", "damping", "T_load"}:
        assert v[name] == d[name], name


def test_derived_values_follow_their_inputs():
    v = resolve({"kL": 1000.0, "Jm": 5e-5, "m": 10, "JL": 0.02, "zeta_t": 0.1, "Fc": 0.04})
    jeq = (5e-5 * 100) * 0.02 / (5e-5 * 100 + 0.02)
    assert equivalent_inertia(v) == pytest.approx(jeq, rel=1e-15)
    assert v["c"] == pytest.approx(2 * 0.1 * math.sqrt(1000.0 * jeq), rel=1e-14)
    assert v["Fs"] == pytest.approx(0.06, rel=1e-15)
    assert v["sigma0"] == pytest.approx(40.0, rel=1e-15)
    assert v["sigma1"] == pytest.approx(2 * 0.5 * math.sqrt(40.0 * 5e-5), rel=1e-14)


def test_explicit_derived_values_are_kept():
    v = resolve({"c": 0.5, "Fs": 0.1, "sigma0": 7.0, "sigma1": 0.01, "kL": 1000, "Fc": 0.05})
    assert (v["c"], v["Fs"], v["sigma0"], v["sigma1"]) == (0.5, 0.1, 7.0, 0.01)


@pytest.mark.parametrize(("name", "raw", "expected"), [
    ("sat1", "off", math.inf), ("sat2", "inf", math.inf), ("sat3", " None ", math.inf),
    ("sat2", math.inf, math.inf), ("friction", "off", 0.0), ("friction", "on", 1.0),
    ("locked", "true", 1.0), ("locked", False, 0.0), ("locked", True, 1.0),
    ("damping", "contact", 0.0), ("damping", "paper", 1.0), ("kL", "600", 600.0),
    ("T_load", -2, -2.0), ("k_h", "-5.5", -5.5), ("alpha", 0, 0.0),
])
def test_check_value_accepts(name, raw, expected):
    assert check_value(name, raw) == expected


@pytest.mark.parametrize(("name", "raw", "match"), [
    ("kL", -1, r"'kL' must be >= 0 \(N\*m/rad\)"),
    ("kL", "abc", r"'kL' expects a number in N\*m/rad, got 'abc'"),
    ("kL", None, r"'kL' expects a number"),
    ("kL", [1], r"'kL' expects a number"),
    ("kL", float("nan"), r"'kL' is NaN"),
    ("kL", "inf", r"'kL' cannot be 'inf'"),
    ("kL", math.inf, r"'kL' must be finite"),
    ("d1", "off", r"'d1' cannot be 'off'"),
    ("damping", 2.0, r"'damping' must be one of contact \(0\), paper \(1\), got 2.0"),
    ("damping", "viscous", r"'damping' must be one of"),
])
def test_check_value_refuses(name, raw, match):
    with pytest.raises(EmaError, match=match):
        check_value(name, raw)


def test_unknown_parameter_lists_the_names():
    with pytest.raises(EmaError) as ei:
        resolve({"kl": 600})
    msg = ei.value.message
    assert "unknown model parameter 'kl'" in msg
    assert all(name in msg for name in INDEX)


@pytest.mark.parametrize(("over", "match"), [
    ({"m": 0}, r"'m' must be > 0"), ({"L": 0.0}, r"'L' must be > 0"),
    ({"Jm": 0}, r"'Jm' must be > 0"), ({"JL": 0}, r"'JL' must be > 0"),
    ({"friction": 3}, r"'friction' must be one of off \(0\), lugre \(1\), static \(2\), got 3"),
    ({"friction": 2, "Fc": 0.02, "Fs": 0.01},
     r"'Fs' \(breakaway friction, 0.01\) must be >= 'Fc'"),
    ({"rigid": 1, "alpha": 0.001}, r"'alpha' \(backlash, 0.001 rad\) needs a compliant"),
    ({"ctrl": "discrete"}, r"the discrete cascade \(ctrl = discrete\) needs a sample time"),
    ({"ctrl": "discrete", "Ts": 1e-3, "dc_ndiff": 0},
     r"'dc_ndiff' \(samples of the velocity's position difference\) must be a whole number "
     r"in 1..16, got 0"),
    ({"ctrl": "discrete", "Ts": 1e-3, "dc_delay": 1.5}, r"'dc_delay' .* whole number in 0..8"),
    ({"locked": 0.5}, r"'locked' must be 0/off or 1/on"),
    ({"friction": 1, "Fc": 0}, r"LuGre friction needs Fc > 0 and vs > 0"),
    ({"friction": 1, "vs": 0}, r"LuGre friction needs Fc > 0 and vs > 0"),
    ({"contact_hc": 1.5}, r"'contact_hc' must be in \[0, 1\] \(-\), got 1.5"),
    ({"contact_hc": -0.1}, r"'contact_hc' must be >= 0"),
    ({"contact_pen": 0}, r"'contact_pen' must be > 0 \(rad\)"),
])
def test_resolve_refuses(over, match):
    with pytest.raises(EmaError, match=match):
        resolve(over)
