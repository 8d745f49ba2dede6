"""The described controller checked against a closed-loop log before anything is fitted.

The law of the actuator description (``model.discrete``: the sampled P/P or PI/PI cascade,
its position filter, velocity difference, limits and computation delay) is applied to the
log's own measured position and reference, sample by sample, with the compiled kernel's
function itself (so the check tests what the simulation will run), and its output compared
with the logged command for every computation delay ``d = 0 .. MAX_DELAY``::

    u_law,d[k] (+ the logged disturbance added to the output)   vs   u_log[k]

Reported: the RMS mismatch per delay relative to the RMS of the logged command, the delay that
fits best, the samples where the law or the log sits at the output limit, and the largest
mismatch with its sample. The law matches at a delay whose relative mismatch is below
:data:`MATCH_MAX`; :func:`chosen_delay` takes the best delay (``auto``) or the one asked for and
refuses, with those figures, a description that matches at none.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ema_cli.errors import EmaError

MATCH_MAX = 0.02  # relative RMS mismatch (of the logged command's RMS) a description may have [-]
AT_LIMIT = 1e-6  # |u| within this fraction of the output limit counts as at the limit [-]


@dataclass
class ControllerCheck:
    """The described law against the logged command.

    rel_rms[d]       RMS(u_law,d - u_log)/RMS(u_log) for each delay d = 0 .. len-1 [-]
    best_delay       the delay with the smallest mismatch [samples]
    described_delay  the description's delay [samples]
    at_limit_log, at_limit_law   samples at the output limit in the log / in the law (best d)
    worst_index, worst_abs       the sample (0-based) and size of the largest mismatch at the
                     best delay [command units]
    u_rms            RMS of the logged command [command units]
    unit             the command's unit (V, N, A)
    """

    rel_rms: list[float]
    best_delay: int
    described_delay: int
    at_limit_log: int
    at_limit_law: int
    worst_index: int
    worst_abs: float
    u_rms: float
    unit: str
    n: int
    law: np.ndarray = field(repr=False, default_factory=lambda: np.zeros(0))

    @property
    def matches(self) -> bool:
        """The law matches the log at its best delay (mismatch below :data:`MATCH_MAX`)."""
        return self.rel_rms[self.best_delay] <= MATCH_MAX

    def summary(self) -> str:
        """One line: the mismatch at the described and the best delay, limit hits."""
        d, b = self.described_delay, self.best_delay
        s = (f"RMS mismatch {100 * self.rel_rms[d]:.3g} % of the command's RMS at the described "
             f"delay of {d} sample(s)")
        if b != d:
            s += f"; {100 * self.rel_rms[b]:.3g} % at {b} sample(s), the best"
        s += (f"; at the output limit: {self.at_limit_log} logged, {self.at_limit_law} by the "
              f"law, of {self.n} samples")
        return s

    def as_dict(self) -> dict[str, Any]:
        """JSON-ready figures."""
        return {"relative_rms_mismatch_by_delay": self.rel_rms, "best_delay": self.best_delay,
                "described_delay": self.described_delay, "matches": self.matches,
                "at_limit_logged": self.at_limit_log, "at_limit_law": self.at_limit_law,
                "worst_index": self.worst_index, "worst_abs": self.worst_abs,
                "command_rms": self.u_rms, "unit": self.unit, "match_max": MATCH_MAX}


def apply_law(params: dict[str, float], q: np.ndarray, r: np.ndarray, delay: int,
              disturbance: np.ndarray | None = None) -> np.ndarray:
    """The described cascade (``params``: the kernel's resolved SI parameters) applied to a
    measured position ``q`` and reference ``r`` (axis units, one value per controller sample)
    -> the command applied at each sample with a delay of ``delay`` samples, plus the logged
    disturbance when given. The speed-sensor source is refused (the log has no speed)."""
    from ema_cli.model.discrete import BUFFER, discrete_sample_nb, filter_coefficient_nb
    from ema_cli.model.params import MAX_FIR

    if params.get("dc_vsrc", 0.0) == 1.0:
        raise EmaError("controller.velocity_source: sensor; the controller check needs the "
                       "encoder source (the log has no speed channel to feed it)")
    taps = np.array([params.get(f"dc_fir{i}", 1.0 if i == 0 else 0.0) for i in range(MAX_FIR)])
    ts = params["Ts"]
    a = filter_coefficient_nb(params.get("dc_vfc", 0.0), ts)
    buf = np.zeros(BUFFER)
    out = np.empty(q.shape[0])
    args = (ts, params["dc_kp"], params.get("dc_ki", 0.0), params.get("dc_vmax", np.inf),
            params["dc_kv"], params.get("dc_kvi", 0.0), params.get("dc_umax", np.inf), 0.0,
            params.get("dc_ndiff", 1.0), taps, a, float(delay))
    for k in range(q.shape[0]):
        out[k] = discrete_sample_nb(buf, float(q[k]), 0.0, float(r[k]), *args)
    if disturbance is not None:
        out = out + disturbance
    return out


def check_controller(params: dict[str, float], q: np.ndarray, r: np.ndarray, u_log: np.ndarray,
                     unit: str = "V", disturbance: np.ndarray | None = None,
                     first: int = 0) -> ControllerCheck:
    """The described law against the logged command ``u_log`` (module docstring); samples
    before ``first`` are left out of the figures (the controller's start-up)."""
    from ema_cli.model.params import MAX_DELAY

    u = np.asarray(u_log, dtype=np.float64)
    sl = slice(first, None)
    u_rms = float(np.sqrt(np.mean(u[sl] ** 2)))
    if u_rms == 0:
        raise EmaError("the logged command is zero on every sample; expected the controller's "
                       "output")
    rel, laws = [], []
    for d in range(MAX_DELAY + 1):
        law = apply_law(params, q, r, d, disturbance)
        laws.append(law)
        rel.append(float(np.sqrt(np.mean((law[sl] - u[sl]) ** 2)) / u_rms))
    best = int(np.argmin(rel))
    err = np.abs(laws[best] - u)
    err[:first] = 0.0
    umax = params.get("dc_umax", np.inf)
    lim_log = int(np.count_nonzero(np.abs(u) >= umax * (1 - AT_LIMIT))) if np.isfinite(umax) else 0
    lim_law = (int(np.count_nonzero(np.abs(laws[best]) >= umax * (1 - AT_LIMIT)))
               if np.isfinite(umax) else 0)
    return ControllerCheck(rel, best, int(params.get("dc_delay", 0.0)), lim_log, lim_law,
                           int(np.argmax(err)), float(err.max()), u_rms, unit, int(u.size),
                           laws[best])


def chosen_delay(check: ControllerCheck, delay: int | str, source: str) -> int:
    """The delay the fit uses: ``"auto"`` the best one, else ``delay`` [samples]; an EmaError
    (one line, with the figures) when the law does not match the log at that delay."""
    d = check.best_delay if delay == "auto" else int(delay)
    if d >= len(check.rel_rms) or d < 0:
        raise EmaError(f"delay {d} samples; expected 0 .. {len(check.rel_rms) - 1} or auto")
    if check.rel_rms[d] <= MATCH_MAX:
        return d
    b = check.best_delay
    if check.rel_rms[b] <= MATCH_MAX:
        raise EmaError(
            f"{source}: the described controller matches the logged command with a delay of "
            f"{b} sample(s) ({100 * check.rel_rms[b]:.3g} % RMS mismatch), not {d} "
            f"({100 * check.rel_rms[d]:.3g} %); use --delay {b} or --delay auto")
    raise EmaError(
        f"{source}: the described controller does not match the logged command: "
        f"{check.summary()}; largest mismatch {check.worst_abs:.4g} {check.unit} at index "
        f"{check.worst_index} (0-based); expected <= {100 * MATCH_MAX:g} % (check the gains, "
        "filter, velocity difference and limit of the description)")
