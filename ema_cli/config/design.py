"""Schema of a design config (``ema design LOG [CONFIG]``): the settings of the two steps that
have any (the identification and the tuning); the acceptance spec is a file of its own.

``identify:`` holds the keys of ``ema identify --closed-loop``'s settings (``free``, ``plant``,
``shooting``, ``channels``, ``columns``, ``window``, ...; ``data`` is the LOG argument), validated
when the design runs. ``tune:`` holds overrides of the tuning config, as nested keys or dotted
paths of it (``optimiser: {pop: 16}`` or ``optimiser.pop: 16``); the tuning config's
``actuator:`` section is replaced by the fitted actuator.
"""

from __future__ import annotations

from typing import Any

from pydantic import Field

from ema_cli.config.base import PlainName, Strict

VERDICTS = ("PASS", "FAIL", "INCONCLUSIVE")
EXIT_CODES = {"PASS": 0, "FAIL": 1, "INCONCLUSIVE": 3}
"""``ema design``'s exit code per verdict (2 stays bad usage or input, as for every command)."""
MAX_FREE_CORNERS = 8  # free parameters whose 2^p interval corners are checked, at most [-]


class DesignConfig(Strict):
    """Everything ``ema design`` takes besides the log, the tuning config and the spec."""

    name: PlainName = Field("design", description="study name (a folder name)")
    identify: dict[str, Any] = Field(
        default_factory=dict, description="settings of the closed-loop identification (keys of "
                                          "`ema identify --closed-loop`; data: the LOG)")
    tune: dict[str, Any] = Field(
        default_factory=dict, description="overrides of the tuning config (its keys, nested or "
                                          "dotted)")
