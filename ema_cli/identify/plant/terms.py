"""Terms of an inverse dynamic model linear in its parameters: named regressor columns built
from the axis' position, velocity and acceleration, and the laws made of them.

An inverse dynamic model writes the actuation force as a sum of terms, each a parameter times a
known function of the motion::

    F(t) = sum_j theta_j * phi_j(q, q', q'')          [N]

A :class:`Term` is one ``(name, unit of theta_j, phi_j)``; a law is a sequence of terms (or of
their names in :data:`TERMS`). The library holds the rigid axis with viscous and Coulomb
friction and an offset, and the same friction per direction of motion (no Stribeck curve: a law
linear in its parameters cannot hold one)::

    rigid (RIGID):          F = M q'' + Fv q' + Fc sign(q') + OF
    per direction (RIGID_PER_DIRECTION, the benchmark's Script_IDIM_LS_Asym_Fric.m):
                            F = M q'' + (Fv+ q' + Fc+) [q' > 0] + (Fv- q' - Fc-) [q' < 0]

with ``sign(0) = 0`` (MATLAB's ``sign``), so a sample at rest carries no friction term. The
per-direction law has no offset: whenever the velocity is never exactly zero,
``[q' > 0] + [q' < 0] = 1`` and the offset column equals the difference of the two Coulomb
columns, so OF, Fc+ and Fc- cannot be told apart (on data with an offset the per-direction
Coulomb estimates are Fc+ + OF and Fc- - OF). ``plant.idim`` refuses such a law, naming the
dependent columns.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from ema_cli.errors import EmaError


@dataclass(frozen=True)
class Kinematics:
    """The motion of the axis at every sample: position ``q_m`` [m], velocity ``dq_m_s`` [m/s],
    acceleration ``ddq_m_s2`` [m/s^2], each of shape [n]."""

    q_m: np.ndarray
    dq_m_s: np.ndarray
    ddq_m_s2: np.ndarray

    def slice(self, start: int, stop: int) -> Kinematics:
        """Samples ``start:stop`` (0-based, stop exclusive)."""
        return Kinematics(self.q_m[start:stop], self.dq_m_s[start:stop],
                          self.ddq_m_s2[start:stop])


@dataclass(frozen=True)
class Term:
    """One term of a law: the parameter's ``name`` and SI ``unit``, what it means, and the
    regressor column ``column(kin) -> [n]`` whose product with the parameter is a force [N]."""

    name: str
    unit: str
    meaning: str
    column: Callable[[Kinematics], np.ndarray]


def _positive(v: np.ndarray) -> np.ndarray:
    """``(1 + sign(v))/2``: 1 moving forward, 0 backward, 1/2 at rest (the script's O_plus)."""
    return (1.0 + np.sign(v)) / 2.0


def _negative(v: np.ndarray) -> np.ndarray:
    """``(1 - sign(v))/2`` (the script's O_minus)."""
    return (1.0 - np.sign(v)) / 2.0


TERMS: dict[str, Term] = {t.name: t for t in (
    Term("M", "kg", "moving mass (load and motor, in load coordinates)",
         lambda k: k.ddq_m_s2),
    Term("Fv", "N*s/m", "viscous friction", lambda k: k.dq_m_s),
    Term("Fc", "N", "Coulomb friction", lambda k: np.sign(k.dq_m_s)),
    Term("OF", "N", "force offset (amplifier or gravity offset)",
         lambda k: np.ones_like(k.dq_m_s)),
    Term("Fv+", "N*s/m", "viscous friction moving forward (q' > 0)",
         lambda k: k.dq_m_s * _positive(k.dq_m_s)),
    Term("Fc+", "N", "Coulomb friction moving forward (q' > 0)",
         lambda k: np.sign(k.dq_m_s) * _positive(k.dq_m_s)),
    Term("Fv-", "N*s/m", "viscous friction moving backward (q' < 0)",
         lambda k: k.dq_m_s * _negative(k.dq_m_s)),
    Term("Fc-", "N", "Coulomb friction moving backward (q' < 0), a magnitude",
         lambda k: np.sign(k.dq_m_s) * _negative(k.dq_m_s)),
)}
"""The library of terms, by name."""

RIGID: tuple[str, ...] = ("M", "Fv", "Fc", "OF")
"""The benchmark's rigid axis (Script_IDIM_LS.m): ``F = M q'' + Fv q' + Fc sign(q') + OF``."""
RIGID_PER_DIRECTION: tuple[str, ...] = ("M", "Fv+", "Fc+", "Fv-", "Fc-")
"""Friction per direction (Script_IDIM_LS_Asym_Fric.m), no offset (see the module's note)."""


def resolve_law(law: Sequence[str | Term]) -> tuple[Term, ...]:
    """The terms of a law given by names (of :data:`TERMS`) or :class:`Term` objects; an
    unknown name, a repeated name or an empty law is an EmaError."""
    terms = []
    for item in law:
        if isinstance(item, Term):
            terms.append(item)
        elif item in TERMS:
            terms.append(TERMS[item])
        else:
            raise EmaError(f"unknown term '{item}' in the law; expected one of "
                           f"{', '.join(TERMS)} or a Term")
    names = [t.name for t in terms]
    if not names:
        raise EmaError("the law has no terms; expected e.g. " + ", ".join(RIGID))
    repeated = sorted({n for n in names if names.count(n) > 1})
    if repeated:
        raise EmaError(f"the law names {', '.join(repeated)} more than once; expected each "
                       "term once")
    return tuple(terms)


def regressors(terms: Sequence[Term], kin: Kinematics) -> np.ndarray:
    """The observation matrix ``W[n, p]`` of ``terms`` on the motion ``kin`` (column j in N per
    unit of parameter j)."""
    n = kin.q_m.shape[0]
    cols = []
    for t in terms:
        c = np.asarray(t.column(kin), dtype=np.float64)
        if c.shape != (n,):
            raise ValueError(f"term '{t.name}' returned shape {c.shape}, expected ({n},)")
        cols.append(c)
    return np.column_stack(cols)
