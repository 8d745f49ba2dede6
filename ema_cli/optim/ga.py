"""A genetic algorithm vectorised over the population: the paper's binary GA and an improved one.

The GA knows nothing of the model. It minimises a :class:`Problem`: bounds ``lower[n_par]``,
``upper[n_par]`` and ``evaluate(X[n_pop, n_par]) -> cost[n_pop]``, called once per generation for
the whole population. All randomness comes from the injected ``np.random.Generator``, so the same
seed gives the same result bit for bit.

Modes (see :func:`preset`):

* ``paper`` — binary coding (``bits`` per parameter), roulette selection on 1/J, single-point
  crossover, bit-flip mutation, no elitism; the result is the best individual of the *final*
  generation ("the individual output with the highest degree of adaptation", paper §3.1).
* ``improved`` — real coding, binary tournament selection, line SBX crossover (children on the
  parents' line, eta_c = 1), polynomial mutation, elitism; the result is the best individual
  ever evaluated (which elitism keeps in the population).

Budget: ``generations`` counts evaluated populations including the initial one, so the paper mode
spends exactly ``pop*generations`` evaluations (100*200 = 20,000); the improved mode re-uses the
elites' costs and spends ``pop + (generations-1)*(pop - elitism)``. Every row passed to
``evaluate`` is counted; nothing is cached or skipped.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field, replace
from typing import Literal, Protocol

import numpy as np

from ema_cli.optim import operators as ops

# defaults (the paper's settings, §3.1, where it gives them)
DEFAULT_POP = 100  # population size [individuals]
DEFAULT_GENERATIONS = 200  # evaluated generations, including the initial one
DEFAULT_PC = 0.85  # crossover probability, per pair of parents
DEFAULT_PM = 0.05  # mutation probability: per bit (binary) or per gene (real)
DEFAULT_BITS = 20  # bits per parameter in binary coding (the paper does not say)
DEFAULT_ELITES = 2  # elites carried unchanged in the improved mode [individuals]
DEFAULT_TOURNAMENT = 2  # tournament size in the improved mode [individuals]
DEFAULT_ETA_C = 15.0  # gene-wise SBX distribution index (the usual NSGA-II value) [-]
LINE_ETA_C = 1.0  # line-SBX distribution index of the improved mode: long steps [-]
DEFAULT_ETA_M = 20.0  # polynomial-mutation distribution index [-]
DEFAULT_EARLY_TOL = 1e-12  # early stopping: relative improvement of best-ever J that counts [-]

Encoding = Literal["binary", "real"]
Crossover = Literal["line-sbx", "sbx"]
Selection = Literal["roulette", "tournament"]
MutationUnit = Literal["bit", "chromosome"]


class Problem(Protocol):
    """What the GA minimises: bounds and a batched cost function."""

    lower: np.ndarray  # [n_par] lower bounds
    upper: np.ndarray  # [n_par] upper bounds

    def evaluate(self, X: np.ndarray) -> np.ndarray:
        """Costs ``J[n_pop]`` of a population ``X[n_pop, n_par]`` (lower is better)."""
        ...


@dataclass(frozen=True)
class GAOptions:
    """GA settings (validated in ``__post_init__``; use :func:`preset` for the two modes).

    pop            population size (>= 2)
    generations    evaluated generations including the initial population (>= 1)
    pc             crossover probability per pair of parents, in [0, 1]
    pm             mutation probability, in [0, 1]: per bit for binary coding with
                   ``mutation_unit="bit"`` (the default), per chromosome with
                   ``mutation_unit="chromosome"`` (one random bit flips), per gene for real coding
    bits           bits per parameter (binary coding), 2..52
    encoding       "binary" (single-point crossover, bit flip) or "real" (SBX, polynomial)
    crossover      real coding: "line-sbx" (one spread factor per pair: children on the parents'
                   line, rotation invariant) or "sbx" (gene-wise, Deb's bounded form)
    selection      "roulette" (proportional to 1/J) or "tournament"
    elitism        number of best individuals copied unchanged into the next generation
    tournament     tournament size
    eta_c, eta_m   SBX and polynomial-mutation distribution indices (real coding)
    report         "final": the best of the last generation; "best_ever": the best seen
    patience       early stopping: stop after this many generations without the best-ever J
                   improving by more than ``early_tol`` (relative); 0 disables it
    """

    pop: int = DEFAULT_POP
    generations: int = DEFAULT_GENERATIONS
    pc: float = DEFAULT_PC
    pm: float = DEFAULT_PM
    bits: int = DEFAULT_BITS
    encoding: Encoding = "real"
    crossover: Crossover = "line-sbx"
    selection: Selection = "tournament"
    elitism: int = DEFAULT_ELITES
    tournament: int = DEFAULT_TOURNAMENT
    eta_c: float = DEFAULT_ETA_C
    eta_m: float = DEFAULT_ETA_M
    mutation_unit: MutationUnit = "bit"
    report: Literal["final", "best_ever"] = "best_ever"
    patience: int = 0
    early_tol: float = DEFAULT_EARLY_TOL

    def __post_init__(self) -> None:
        checks = [
            (self.pop >= 2, f"population must be >= 2, got {self.pop}"),
            (self.generations >= 1, f"generations must be >= 1, got {self.generations}"),
            (0.0 <= self.pc <= 1.0, f"pc must be in [0, 1], got {self.pc}"),
            (0.0 <= self.pm <= 1.0, f"pm must be in [0, 1], got {self.pm}"),
            (ops.MIN_BITS <= self.bits <= ops.MAX_BITS,
             f"bits must be in [{ops.MIN_BITS}, {ops.MAX_BITS}], got {self.bits}"),
            (self.encoding in ("binary", "real"), f"unknown encoding {self.encoding!r}"),
            (self.crossover in ("line-sbx", "sbx"), f"unknown crossover {self.crossover!r}"),
            (self.selection in ("roulette", "tournament"), f"unknown selection {self.selection!r}"),
            (0 <= self.elitism < self.pop,
             f"elitism must be in [0, pop-1] = [0, {self.pop - 1}], got {self.elitism}"),
            (self.tournament >= 1, f"tournament size must be >= 1, got {self.tournament}"),
            (self.eta_c >= 0 and self.eta_m >= 0, "eta_c and eta_m must be >= 0"),
            (self.mutation_unit in ("bit", "chromosome"),
             f"unknown mutation unit {self.mutation_unit!r}"),
            (self.report in ("final", "best_ever"), f"unknown report {self.report!r}"),
            (self.patience >= 0, f"patience must be >= 0, got {self.patience}"),
        ]
        for ok, msg in checks:
            if not ok:
                raise ValueError(msg)

    @property
    def budget(self) -> int:
        """Fitness evaluations of a full run (no early stop)."""
        return self.pop + (self.generations - 1) * (self.pop - self.elitism)


class IterationLog:
    """The history of a local search, one entry per iteration (a batch of candidates)."""

    def __init__(self, n: int) -> None:
        self.n = n
        self.best: list[float] = []
        self.mean: list[float] = []
        self.ever: list[float] = []
        self.xs: list[np.ndarray] = []
        self.evals: list[int] = []

    def add(self, fc: np.ndarray, f_best: float, x_best: np.ndarray, used: int) -> None:
        """One iteration: its candidates' costs ``fc`` (NaN already inf), the best so far and
        the evaluations used so far."""
        finite = fc[np.isfinite(fc)]
        self.best.append(float(fc.min()))
        self.mean.append(float(finite.mean()) if finite.size else np.inf)
        self.ever.append(float(f_best))
        self.xs.append(np.array(x_best, dtype=np.float64))
        self.evals.append(int(used))

    def history(self) -> GAHistory:
        xs = np.array(self.xs).reshape(-1, self.n)
        return GAHistory(np.array(self.best), np.array(self.mean), np.array(self.ever), xs,
                         xs.copy(), np.array(self.evals, dtype=np.int64))


def preset(mode: Literal["paper", "improved"], **overrides: object) -> GAOptions:
    """The options of a mode, with ``overrides`` (any GAOptions field) applied on top."""
    if mode == "paper":
        base = GAOptions(encoding="binary", selection="roulette", elitism=0, report="final",
                         mutation_unit="bit")
    elif mode == "improved":
        base = GAOptions(encoding="real", crossover="line-sbx", eta_c=LINE_ETA_C,
                         selection="tournament", elitism=DEFAULT_ELITES, report="best_ever")
    else:
        raise ValueError(f"mode must be 'paper' or 'improved', got {mode!r}")
    return replace(base, **overrides)  # type: ignore[arg-type]


@dataclass
class GAHistory:
    """Per-generation record (``n_gen`` rows; costs in the problem's units).

    best[n_gen]             lowest J of the generation
    mean[n_gen]             mean of the generation's finite J
    best_ever[n_gen]        lowest J seen so far
    x_best[n_gen, n_par]    parameters of the generation's best
    x_best_ever[n_gen, n_par]
    evaluations[n_gen]      cumulative fitness evaluations
    """

    best: np.ndarray
    mean: np.ndarray
    best_ever: np.ndarray
    x_best: np.ndarray
    x_best_ever: np.ndarray
    evaluations: np.ndarray


@dataclass
class GAResult:
    """Outcome of one GA run: the reported point (per ``options.report``) and the history."""

    x: np.ndarray  # reported parameters [n_par]
    cost: float  # J at x
    x_best_ever: np.ndarray
    cost_best_ever: float
    evaluations: int  # fitness evaluations actually made
    generations: int  # generations evaluated (less than asked when stopped early)
    stopped_early: bool
    wall_time_s: float
    history: GAHistory = field(repr=False)


def _evaluate(problem: Problem, X: np.ndarray) -> np.ndarray:
    cost = np.asarray(problem.evaluate(X), dtype=np.float64)
    if cost.shape != (X.shape[0],):
        raise ValueError(f"problem.evaluate returned shape {cost.shape}, expected ({X.shape[0]},)")
    return np.where(np.isnan(cost), np.inf, cost)


def run_ga(problem: Problem, options: GAOptions, rng: np.random.Generator) -> GAResult:
    """Minimise ``problem`` with the GA described by ``options``, drawing from ``rng`` only."""
    t0 = time.perf_counter()
    lower = np.asarray(problem.lower, dtype=np.float64)
    upper = np.asarray(problem.upper, dtype=np.float64)
    if lower.ndim != 1 or lower.shape != upper.shape or not np.all(upper > lower):
        raise ValueError("problem bounds must be 1-D arrays with upper > lower")
    o = options
    binary = o.encoding == "binary"
    n_par = lower.shape[0]

    def phenotype(G: np.ndarray) -> np.ndarray:
        return ops.decode(G, lower, upper, o.bits) if binary else G

    genome = (ops.random_binary(rng, o.pop, n_par * o.bits) if binary
              else ops.random_real(rng, o.pop, lower, upper))
    X = phenotype(genome)
    cost = _evaluate(problem, X)
    n_eval = o.pop

    hist_best = np.empty(o.generations)
    hist_mean = np.empty(o.generations)
    hist_ever = np.empty(o.generations)
    hist_x = np.empty((o.generations, n_par))
    hist_xe = np.empty((o.generations, n_par))
    hist_eval = np.empty(o.generations, dtype=np.int64)
    ever_x, ever_cost = X[0].copy(), np.inf
    stale, stopped, n_gen = 0, False, 0

    from ema_cli.progress import report

    for gen in range(o.generations):
        report("GA generation", gen + 1, o.generations)
        if gen > 0:
            order = np.argsort(cost, kind="stable")
            elite = order[: o.elitism]
            n_off = o.pop - o.elitism
            n_sel = n_off + n_off % 2
            if o.selection == "roulette":
                parents = ops.roulette(rng, cost, n_sel)
            else:
                parents = ops.tournament(rng, cost, n_sel, o.tournament)
            if binary:
                child = ops.single_point_crossover(rng, genome[parents], o.pc)
                child = ops.bit_flip(rng, child, o.pm, o.mutation_unit)
            else:
                cross = ops.line_sbx if o.crossover == "line-sbx" else ops.sbx
                child = cross(rng, genome[parents], lower, upper, o.pc, o.eta_c)
                child = ops.polynomial_mutation(rng, child, lower, upper, o.pm, o.eta_m)
            child = child[:n_off]
            child_cost = _evaluate(problem, phenotype(child))
            n_eval += n_off
            genome = np.concatenate([genome[elite], child])
            cost = np.concatenate([cost[elite], child_cost])
            X = phenotype(genome)
        i_best = int(np.argmin(cost))
        improved = cost[i_best] < ever_cost
        if improved:
            significant = ever_cost - cost[i_best] > o.early_tol * abs(ever_cost)
            ever_cost, ever_x = float(cost[i_best]), X[i_best].copy()
            stale = 0 if significant else stale + 1
        else:
            stale += 1
        finite = cost[np.isfinite(cost)]
        hist_best[gen] = cost[i_best]
        hist_mean[gen] = finite.mean() if finite.size else np.inf
        hist_ever[gen] = ever_cost
        hist_x[gen] = X[i_best]
        hist_xe[gen] = ever_x
        hist_eval[gen] = n_eval
        n_gen = gen + 1
        if o.patience and stale >= o.patience and gen < o.generations - 1:
            stopped = True
            break

    history = GAHistory(hist_best[:n_gen], hist_mean[:n_gen], hist_ever[:n_gen],
                        hist_x[:n_gen], hist_xe[:n_gen], hist_eval[:n_gen])
    if o.report == "final":
        x_rep, c_rep = hist_x[n_gen - 1].copy(), float(hist_best[n_gen - 1])
    else:
        x_rep, c_rep = ever_x, ever_cost
    return GAResult(x_rep, c_rep, ever_x, ever_cost, n_eval, n_gen, stopped,
                    time.perf_counter() - t0, history)
