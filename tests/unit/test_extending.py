"""The end points of docs/extending.md: tests that fail until a new nonlinearity or acceptance
test kind is complete (a new command ends at test_cli_routes and test_result_contract)."""

from __future__ import annotations

import numpy as np
import pytest

from ema_cli import api
from ema_cli.model.nonlinearities import PLACEMENTS

VISIBLE = {"deadzone1": 1.0, "deadzone2": 0.1, "deadzone3": 10.0, "deadzone4": 0.1,
           "saturation1": 10.0, "saturation2": 1.0, "saturation3": 0.5, "gap1": 0.01,
           "friction1": 0.1}
"""A magnitude (edge unit) of each nonlinearity that a 1 deg step must feel. Measured
(0.05 s): the load angle moves 0.04 deg (deadzone3) to 0.54 deg (saturation1) from the
default run's."""
NEUTRAL = {"deadzone1": 0.0, "deadzone2": 0.0, "deadzone3": 0.0, "deadzone4": 0.0}
"""Magnitudes that must leave the default run bit for bit unchanged (a dead zone of 0)."""
STEP = {"simulation": {"duration_s": 0.05}, "input": {"kind": "step", "amplitude_deg": 1.0}}
FELT_DEG = 1e-3  # smallest change of the load angle that counts as felt [deg] (40x below
# the smallest measured above)


@pytest.fixture(scope="module")
def default_run():
    return api.simulate(STEP)


@pytest.mark.parametrize("pl", PLACEMENTS, ids=lambda pl: pl.alias)
def test_every_nonlinearity_reaches_the_kernel(pl, default_run):
    assert pl.alias in VISIBLE, f"{pl.alias}: add a magnitude a 1 deg step feels to VISIBLE"
    run = api.simulate(STEP, nl={pl.alias: VISIBLE[pl.alias]})
    moved = np.max(np.abs(run.signal("theta_load_deg") - default_run.signal("theta_load_deg")))
    assert moved > FELT_DEG, f"{pl.alias} = {VISIBLE[pl.alias]} {pl.unit} changes nothing"


@pytest.mark.parametrize("name", list(NEUTRAL))
def test_a_neutral_magnitude_changes_nothing(name, default_run):
    run = api.simulate(STEP, nl={name: NEUTRAL[name]})
    np.testing.assert_array_equal(run.signal("theta_load_deg"),
                                  default_run.signal("theta_load_deg"))
