"""The integrator a kernel variant shares (``sim.variants.rates_key``): the variants with one key
must need the same compiled integration, or a variant would run another's state equations.

Checked against the definitions the kernel compiles from, not against the key's own bit list:
every flag the generated state equations read (their holds, the states they integrate, the
flags bound to the rates' arguments) and the choice of the switch search (``hybrid``) are
equal for a code and its key, over every combination of the variant bits; the generated source
itself is compared on a fixed sample of codes.
"""

from __future__ import annotations

import inspect
import itertools

import numpy as np

from ema_cli.model import actuator
from ema_cli.model.actuator import (
    B_AMP,
    B_AMP_BW,
    B_CTRL,
    B_EXT,
    B_EXTRAS,
    B_FRIC_L,
    B_RIGID,
    B_THERMAL,
    B_TRANS,
)
from ema_cli.model.states import STATES
from ema_cli.sim import layout
from ema_cli.sim.variants import VARIANTS, rates_key


def _all_codes() -> list[int]:
    codes = []
    for fm, ex, rg, amp, ctrl, fl, ext, tr, th in itertools.product(
            range(4), (0, 1), (0, 1), (0, 1, 2), range(3), range(3), (0, 1), (0, 1), (0, 1)):
        amp_bits = (0, 1 << B_AMP, (1 << B_AMP) | (1 << B_AMP_BW))[amp]
        codes.append(fm | (ex << B_EXTRAS) | (rg << B_RIGID) | amp_bits | (fl << B_FRIC_L)
                     | (ctrl << B_CTRL) | (ext << B_EXT) | (tr << B_TRANS) | (th << B_THERMAL))
    return codes


def _flags_read() -> set[str]:
    """The flags the generated state equations depend on (``sim.layout.source``)."""
    read = {"static_m", "static_L", "rigid", "hybrid"}  # the holds on the static sites
    for s in STATES:
        if s.kind != "rk4":
            continue
        read.update(s.active)
        read.update(c for c in s.hold if c in actuator.FLAGS)
        fn = s.rate.py_func if hasattr(s.rate, "py_func") else s.rate
        read.update(a for a in inspect.signature(fn).parameters if a in actuator.FLAGS)
    return read


def test_a_code_and_its_key_agree_on_every_flag_the_integration_reads():
    read = _flags_read()
    assert {"amp", "thermal", "fric_L", "amp_bw", "trans", "static_m"} <= read  # sanity
    codes = _all_codes()
    assert len(codes) == 3456
    keys = set()
    for code in codes:
        key = rates_key(code)
        keys.add(key)
        a, b = actuator.flags_of(code), actuator.flags_of(key)
        for f in read:
            assert getattr(a, f) == getattr(b, f), (code, key, f)
        assert rates_key(key) == key  # a key is its own key
    # the keys are few: the codes that differ only in what the integrator reads at run time
    # (controller, extras, motor LuGre law, input signal) share one
    assert len(keys) == 2 * 2 * 3 * 3 * 2 * 2


def test_a_code_and_its_key_generate_the_same_state_equations():
    rng = np.random.default_rng(39)
    codes = _all_codes()
    sample = [codes[i] for i in rng.choice(len(codes), 120, replace=False)]
    for code in sample + list(range(7)):
        assert layout.source(variant=code) == layout.source(variant=rates_key(code)), code


def test_the_paper_ema_variants_share_one_integrator():
    # one RK4 (and no switch search) compiled for every variant `ema compile` makes ahead
    assert {rates_key(v) for w in VARIANTS.values() for v in w} == {0}
    assert not actuator.flags_of(0).hybrid
    static = 3 | (1 << B_EXTRAS)
    assert actuator.flags_of(rates_key(static)).hybrid
