"""The multirate method against brute force: the bundled TVC endurance profile with every cycle
count divided by 100 (310 s of motion), simulated once more at the mechanical step with the
thermal network inside the kernel (its states th_w, th_h; R(T) in the armature's equation).
The multirate peak winding temperature must be within 0.5 K of it (issue 40)."""

from __future__ import annotations

from pathlib import Path

import pytest

from ema_cli.api.duty import duty

ROOT = Path(__file__).resolve().parents[2]
TVC = ROOT / "configs" / "duty" / "tvc.yaml"
CYCLES = (3700, 4800, 5000, 7000, 8500, 1500)


def hundredth() -> dict[str, int]:
    """The overrides dividing every block's cycle count by 100."""
    return {f"segments.{k}.sine.cycles": c // 100 for k, c in enumerate(CYCLES)}


@pytest.mark.slow
def test_multirate_peak_within_half_a_kelvin_of_full_resolution() -> None:
    res = duty(TVC, overrides=hundredth(), full_resolution=True, hot=False)
    ref = res.reference
    assert ref is not None and ref.steps > 3_000_000  # 310 s at the reference EMA's 10 us
    assert res.expanded.duration == pytest.approx(sum(c // 100 / f for c, f in zip(
        CYCLES, (0.3, 0.6, 1, 2, 5, 3), strict=True)), rel=1e-9)
    rise = ref.peak_w - ref.t_w[0]
    assert rise > 15.0  # the winding warms: the comparison means something
    assert abs(res.run.thermal.peak_w - ref.peak_w) < 0.5
    # and the temperature at the end of the profile (the housing too) agrees
    tr = res.trace()
    assert abs(tr.winding_c.iloc[-1] + 273.15 - ref.t_w[-1]) < 0.5
    assert abs(tr.housing_c.iloc[-1] + 273.15 - ref.t_h[-1]) < 0.5
