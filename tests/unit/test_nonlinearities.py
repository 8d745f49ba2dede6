"""model/nonlinearities.py: each placement's parameter update in SI, 'off', bad magnitudes,
unknown names, and the table of docs/model.md §5.

Conversions are written out here (math.radians, 2*pi/60) rather than taken from ema_cli.units.
"""

from __future__ import annotations

import math
import re
from pathlib import Path

import pytest

from ema_cli.errors import EmaError
from ema_cli.model.nonlinearities import (
    ALIASES,
    BY_KEY,
    LOCATIONS,
    PLACEMENTS,
    TYPES,
    lookup,
    nonlinearity_updates,
)
from ema_cli.model.params import INDEX, resolve

MODEL_MD = Path(__file__).resolve().parents[2] / "docs" / "model.md"
RPM = 2 * math.pi / 60
BASE = resolve()


def doc_rows() -> list[list[str]]:
    text = MODEL_MD.read_text(encoding="utf-8")
    text = text[text.index("## 5. The nine nonlinearity locations"):]
    rows = [[c.strip() for c in line.strip().strip("|").split("|")]
            for line in text.splitlines() if line.startswith("| `")]
    return rows[:9]


def test_registry_is_consistent():
    assert len(PLACEMENTS) == 9 and len(ALIASES) == 9 and len(BY_KEY) == 9
    for pl in PLACEMENTS:
        assert lookup(pl.alias) is pl and lookup(f"{pl.type}@{pl.location}") is pl
    assert TYPES == ["compliance", "deadzone", "friction", "saturation"]
    assert set(LOCATIONS) == {pl.location for pl in PLACEMENTS}


def test_doc_table_matches_registry():
    rows = doc_rows()
    assert [r[0].strip("`") for r in rows] == [pl.alias for pl in PLACEMENTS]
    for r in rows:
        pl = lookup(r[0].strip("`"))
        assert r[1].strip("`") == f"{pl.type}@{pl.location}"
        assert r[3].replace("·", "*") == pl.unit, r
        assert r[5] == pl.default, r
        # "sets (SI)" names exactly the parameters a magnitude > 0 updates
        named = set(re.findall(r"`(\w+)", r[4]))
        value = 1.0 if pl.default == "off" else pl.default
        assert named == set(nonlinearity_updates(pl.alias, value, BASE)), r


def test_defaults_reproduce_the_parameter_table():
    # each placement's default magnitude gives the model's default parameter value
    for pl in PLACEMENTS:
        if pl.type == "friction":
            assert nonlinearity_updates(pl.alias, pl.default, BASE) == {"friction": 0.0}
            continue
        upd = nonlinearity_updates(pl.alias, pl.default, BASE)
        for name, value in upd.items():
            # 1.024*24^2 = 589.8 vs kL = 590; 30.35 exact; 800 deg/s exact
            assert value == pytest.approx(BASE[name], rel=5e-4), (pl.alias, name)


@pytest.mark.parametrize(("name", "value", "expected"), [
    ("deadzone1", 0.1, {"d1": 0.1}),
    ("deadzone@amplifier", "1", {"d1": 1.0}),
    ("deadzone2", 0.01, {"alpha": math.radians(0.01)}),
    ("deadzone@transmission", 0.1, {"alpha": math.radians(0.1)}),
    ("deadzone3", 10, {"d3": 10 * RPM}),
    ("deadzone@speed_sensor", 0.1, {"d3": 0.1 * RPM}),
    ("deadzone4", 0.001, {"d4": math.radians(0.001)}),
    ("deadzone@position_sensor", "0.01", {"d4": math.radians(0.01)}),
    ("saturation1", 800, {"sat1": math.radians(800)}),
    ("saturation@position_regulator", 100.5, {"sat1": math.radians(100.5)}),
    ("saturation2", 40, {"sat2": 40.0}),
    ("saturation@speed_regulator", "12", {"sat2": 12.0}),
    ("saturation3", 30.35, {"sat3": 30.35}),
    ("saturation@current", 5, {"sat3": 5.0}),
    # gap1 sets the stiffness only (the dead band is deadzone2's), m = 24 -> m^2 = 576
    ("gap1", 1.024, {"kL": 1.024 * 576}),
    ("compliance@transmission", 0.01, {"kL": 0.01 * 576}),
    ("friction1", 0.001, {"friction": 1.0, "sigma2": 0.001}),
    ("friction@motor_shaft", 0, {"friction": 0.0}),  # magnitude 0: no friction
])
def test_updates_in_si(name, value, expected):
    got = nonlinearity_updates(name, value, BASE)
    assert set(got) == set(expected)
    for k, v in expected.items():
        assert got[k] == pytest.approx(v, rel=1e-14, abs=0.0), k
    assert set(got) <= set(INDEX)


def test_gap1_uses_the_given_gear_ratio():
    assert nonlinearity_updates("gap1", 2.0, {**BASE, "m": 10.0}) == {"kL": 200.0}


@pytest.mark.parametrize(("name", "expected"), [
    ("deadzone1", {"d1": 0.0}), ("deadzone2", {"alpha": 0.0}), ("deadzone3", {"d3": 0.0}),
    ("deadzone4", {"d4": 0.0}), ("saturation1", {"sat1": math.inf}),
    ("saturation2", {"sat2": math.inf}), ("saturation3", {"sat3": math.inf}),
    ("friction1", {"friction": 0.0}),
])
@pytest.mark.parametrize("word", ["off", "OFF", " Off "])
def test_off(name, expected, word):
    assert nonlinearity_updates(name, word, BASE) == expected


def test_gap1_cannot_be_off_or_zero():
    with pytest.raises(EmaError, match=r"'gap1' cannot be 'off'"):
        nonlinearity_updates("gap1", "off", BASE)
    with pytest.raises(EmaError, match=r"'gap1' stiffness must be > 0"):
        nonlinearity_updates("gap1", 0, BASE)


@pytest.mark.parametrize("name", ["saturation1", "saturation@speed_regulator", "saturation3"])
def test_saturation_zero_refused(name):
    with pytest.raises(EmaError, match=rf"'{name}' limit must be > 0 .* \(or 'off'\), got 0"):
        nonlinearity_updates(name, 0.0, BASE)


@pytest.mark.parametrize("name", [pl.alias for pl in PLACEMENTS]
                         + ["deadzone@transmission", "saturation@current"])
@pytest.mark.parametrize("value", [-0.1, "-1", float("nan"), "nan", math.inf, "inf"])
def test_bad_magnitude_names_the_setting(name, value):
    pl = lookup(name)
    with pytest.raises(EmaError) as ei:
        nonlinearity_updates(name, value, BASE)
    msg = ei.value.message
    assert f"'{name}'" in msg and "finite number >= 0" in msg and pl.unit in msg


@pytest.mark.parametrize("name", ["deadzone2", "saturation2", "gap1", "friction1"])
def test_non_number_string_names_the_setting(name):
    with pytest.raises(EmaError, match=rf"'{name}' expects a number in .*, got 'abc'"):
        nonlinearity_updates(name, "abc", BASE)


@pytest.mark.parametrize("value", [True, False])
def test_boolean_is_not_a_magnitude(value):
    # YAML reads yes/no/true/false as booleans; float(True) would silently be 1 deg
    with pytest.raises(EmaError, match=rf"'deadzone2' expects a number in deg or off, got the "
                                       rf"boolean {str(value).lower()}"):
        nonlinearity_updates("deadzone2", value, BASE)


def test_unknown_name_lists_valid_names():
    with pytest.raises(EmaError) as ei:
        nonlinearity_updates("deadzone5", 0.1, BASE)
    msg = ei.value.message
    assert "unknown nonlinearity 'deadzone5'" in msg
    assert all(a in msg for a in ALIASES) and all(k in msg for k in BY_KEY)


@pytest.mark.parametrize(("name", "match"), [
    ("backlash@transmission", r"unknown nonlinearity type 'backlash'; expected one of \['comp"),
    ("deadzone@gearbox", r"unknown location 'gearbox'; expected one of \["),
    ("saturation@amplifier",
     r"a saturation cannot be placed at 'amplifier'; possible locations: \['current', "
     r"'position_regulator', 'speed_regulator'\]"),
])
def test_type_location_errors(name, match):
    with pytest.raises(EmaError, match=match):
        lookup(name)


def test_friction_scale_reading():
    got = nonlinearity_updates("friction1", 0.05, BASE, "scale")
    s0 = 1e3 * 0.05
    expected = {"friction": 1.0, "Fc": 0.05, "Fs": 0.075, "sigma0": s0,
                "sigma1": math.sqrt(s0 * 3e-5), "sigma2": 1e-4}
    assert set(got) == set(expected)
    for k, v in expected.items():
        assert got[k] == pytest.approx(v, rel=1e-14), k
    assert nonlinearity_updates("friction1", 0, BASE, "scale") == {"friction": 0.0}
    assert nonlinearity_updates("friction1", 0.0, BASE) == {"friction": 0.0}
    assert nonlinearity_updates("friction1", "off", BASE, "scale") == {"friction": 0.0}


def test_friction_reading_must_be_known():
    with pytest.raises(EmaError, match=r"friction reading must be one of \('sigma2', 'scale'\)"):
        nonlinearity_updates("friction1", 0.01, BASE, "coulomb")


@pytest.mark.parametrize("value", [None, [1], {"a": 1}])
def test_a_magnitude_that_is_not_a_number_is_named(value):
    with pytest.raises(EmaError, match="'deadzone2' expects a number"):
        nonlinearity_updates("deadzone2", value, resolve())
