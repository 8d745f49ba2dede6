"""The paper's EMA is unchanged by actuator descriptions: every kernel variant of the reference
EMA (friction laws, the digital controller, quantisers, compensators, the locked motor,
backlash forms, load profiles), every entry point (one lane and lanes, serial and parallel)
and time chunks give the signals and metrics fingerprinted before the kernel was laid out by
name (``tests/goldens/kernel.json``, ``experiments/goldens.py``), bit for bit.

Fused multiply-adds are compiled for the host CPU, so the fingerprints hold for the CPU kind
they were recorded on; on another the comparison is skipped (say so, never pass silently)."""

from __future__ import annotations

import importlib.util
import json
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
GOLDENS = ROOT / "tests" / "goldens" / "kernel.json"


def _goldens_module():
    spec = importlib.util.spec_from_file_location("goldens", ROOT / "experiments" /
                                                  "goldens.py")
    mod = importlib.util.module_from_spec(spec)  # type: ignore[arg-type]
    spec.loader.exec_module(mod)  # type: ignore[union-attr]
    return mod


def test_the_paper_ema_is_bit_identical_to_its_fingerprints():
    g = _goldens_module()
    ref = json.loads(GOLDENS.read_text())
    if ref["cpu"] != g._cpu():
        pytest.skip(f"fingerprints recorded on {ref['cpu']['model']!r}, this CPU differs")
    got = g.fingerprints()
    assert len(ref["cases"]) == 132
    bad = sorted(k for k, v in ref["cases"].items() if got.get(k) != v)
    assert bad == []
