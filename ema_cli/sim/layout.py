"""The kernel's work array, laid out by name from the tables, and the code that reads it.

A chunk of lanes is one work array ``W[N_ROWS, lanes]`` (structure of arrays: the lane axis
innermost, so the compiler vectorises the lane loop). Its rows, in order, each group from one
table::

    params      model.params.PARAMS            (P's columns, copied in at the start)
    derived     DERIVED                        (constants computed once from the parameters)
    memory      MEMORY                         (controller memory, status, friction modes)
    buffer      model.discrete.BUFFER rows      (the discrete cascade's history and delay line)
    states      model.states.STATES
    acc         sim.tables.ACCUMULATORS        (the metrics' running sums, maxima, instants)
    inputs      INPUTS                         (this step's reference, load profile, input signal)
    recorded    sim.tables.SIGNALS             (this step's recorded values)

Nothing reads a row by a literal index: ``ROW[name]`` (or the group offsets) gives it. The code
that moves a group between the work array and named tuples in registers -- and the RK4 stage
and combination over the ``rk4`` states, the state equations bound by argument name, the
metric accumulators' updates and the recorded signals -- is *generated* from the tables
(:func:`source`) when this module is imported and compiled inline into the kernel's entry
points, which numba caches (the cache is keyed on every source of ``model/`` and ``sim/``:
``ema_cli._numba``). So a new state is one row of ``model.states.STATES`` and its equation; a
new metric one accumulator row and one metric row (docs/extending.md).
"""

from __future__ import annotations

import ast
import inspect
from collections import namedtuple
from typing import Any

from numba.extending import overload

from ema_cli._numba import literally, njit
from ema_cli.model import actuator, discrete
from ema_cli.model.params import FLAGS as FLAG_PARAMS
from ema_cli.model.params import PARAMS
from ema_cli.model.states import STATES
from ema_cli.sim.tables import ACCUMULATORS, SETTLE_BAND, SIGNALS

DERIVED: tuple[tuple[str, str], ...] = (
    ("inv_m", "1/m"),
    ("inv_L", "1/L"),
    ("inv_Jm", "1/Jm"),
    ("inv_JL", "1/JL"),
    ("inv_Jtot", "1/(JL + m^2 Jm): the rigid axis's inertia"),
    ("contact", "the contact damping form (damping == 0)"),
    ("ns", "steps per controller sample (0: continuous)"),
    ("is_step", "the reference is a step"),
    ("step", "the step's final value"),
    ("t_step", "the step's time"),
    ("inv_qp", "1/q_pos (0: no quantiser)"),
    ("inv_qs", "1/q_speed (0: no quantiser)"),
    ("nw", "notch: w [rad/s]"),
    ("nc", "notch: output gain"),
    ("inv_tau", "1/contact_tau (inf: the jump form)"),
    ("hck", "contact_hc/contact_pen"),
    ("t_const", "T_load - offset: the constant external torque on the load"),
    ("inv_amp_tau", "1/amp_tau"),
    ("a_vf", "the discrete cascade's velocity filter coefficient"),
    ("th_r0", "thermal: R at ambient, R*(1 + alpha_cu*(T_amb - T_ref))"),
    ("th_ra", "thermal: R*alpha_cu (R = th_r0 + th_ra*th_w)"),
    ("th_gwh", "thermal: 1/Rth_wh"),
    ("th_gha", "thermal: 1/Rth_ha"),
    ("th_icw", "thermal: 1/Cth_w"),
    ("th_ich", "thermal: 1/Cth_h"),
)
"""Constants derived once per lane from its parameters (``sim.kernel._init`` computes them)."""
BOOL_DERIVED = ("contact", "is_step")
MEMORY: tuple[tuple[str, str], ...] = (
    ("cnt", "steps until the next controller sample"),
    ("uh", "the held controller command"),
    ("alive", "1 while the lane runs, 0 once it diverged"),
    ("kend", "the step it diverged at (n_steps + 1: never)"),
    ("xn1", "notch state 1"),
    ("xn2", "notch state 2"),
    ("zh", "friction observer's bristle state"),
    ("stuck_m", "1 while the motor's static friction sticks"),
    ("dir_m", "the motor's slip direction (+-1)"),
    ("stuck_L", "1 while the load's (a rigid axis's) static friction sticks"),
    ("dir_L", "the load's slip direction (+-1)"),
)
INPUTS: tuple[tuple[str, str], ...] = (
    ("r0", "reference at t"), ("r1", "reference at t + dt/2"), ("r2", "reference at t + dt"),
    ("rv", "reference velocity at t"),
    ("l0", "load profile at t"), ("l1", "load profile at t + dt/2"),
    ("l2", "load profile at t + dt"),
    ("e0", "input signal at t"), ("e1", "input signal at t + dt/2"),
    ("e2", "input signal at t + dt"),
)
OUT: tuple[str, ...] = ("u_out", "u_amp", "t_shaft", "t_fric", "t_load", "f_drive", "f_fric_L",
                        "cur")
"""What a step computes at its instant for the metrics and the recorded signals: the command
sent, the amplifier input, the shaft torque, the motor friction, the external torque on the
load, the drive's force on the axis, the load friction, the motor current (armature) or the
current the drive's torque stands for (``T_d/Kt``)."""
STEP: tuple[str, ...] = ("e", "ev", "ae", "aev", "wgt", "t", "k", "in_ss", "in_osc", "act",
                         "s", "cur", "u_out", "w_L", "t_shaft")
"""The quantities of a step the metric accumulators read (``sim.tables.ACCUMULATORS``)."""

# ---- the rows --------------------------------------------------------------------------------
_groups = (("param", [p.name for p in PARAMS]), ("derived", [d for d, _ in DERIVED]),
           ("memory", [m for m, _ in MEMORY]),
           ("buffer", [f"buf{k}" for k in range(discrete.BUFFER)]),
           ("state", [s.name for s in STATES]), ("acc", [a.name for a in ACCUMULATORS]),
           ("input", [i for i, _ in INPUTS]), ("rec", [c.name for c in SIGNALS]))
ROW: dict[str, int] = {}
"""Row of every named quantity in the work array (states, memory, ... by their own name;
parameters by theirs; recorded signals as ``rec.<signal>``)."""
START: dict[str, int] = {}
"""First row of each group."""
_r = 0
for _group, _names in _groups:
    START[_group] = _r
    for _n in _names:
        key = f"rec.{_n}" if _group == "rec" else _n
        if key in ROW:
            raise ValueError(f"the name {key!r} is used twice in the kernel's layout")
        ROW[key] = _r
        _r += 1
N_ROWS = _r
"""Rows of a work array."""
R = namedtuple("Rows", [k.replace(".", "_") for k in ROW])(*ROW.values())  # type: ignore[misc]
"""The rows by attribute (``R.friction``, ``R.rec_theta_ref``): a constant the compiled code
reads (numba folds a global named tuple's fields)."""

LANE_FIELDS = tuple([p.name for p in PARAMS] + [d for d, _ in DERIVED])
Lane = namedtuple("Lane", LANE_FIELDS)  # type: ignore[misc]
"""A lane's parameters and derived constants by name (flags and switches as booleans)."""
X = namedtuple("X", [s.name for s in STATES])  # type: ignore[misc]
"""A lane's state by name (``model.states.STATES`` order)."""
Mem = namedtuple("Mem", [m for m, _ in MEMORY])  # type: ignore[misc]
Acc = namedtuple("Acc", [a.name for a in ACCUMULATORS])  # type: ignore[misc]
Inp = namedtuple("Inp", [i for i, _ in INPUTS])  # type: ignore[misc]
Out = namedtuple("Out", OUT)  # type: ignore[misc]
Step = namedtuple("Step", STEP)  # type: ignore[misc]
BOOL_LANE = tuple(FLAG_PARAMS) + BOOL_DERIVED
"""Lane fields read as flags (``row != 0``)."""


# ---- the generated code ------------------------------------------------------------------------
RATE_ORDER = ("i", "xI", "w_m", "w_L")
"""The state equations evaluated first, in this order (the rest in table order): the order the
paper's kernel always evaluated them in. A rate with a condition (the current limit, the
anti-windup) may split the compiled code into blocks, and which multiply-adds the compiler fuses
depends on the block an operation lands in: this order keeps the paper's EMA bit for bit."""
CONSTANTS = {"SETTLE_BAND": SETTLE_BAND}
"""Named constants the tables' expressions may use."""
_BUILTINS = ("abs", "min", "max")


def _names_in(expr: str) -> list[str]:
    return sorted({n.id for n in ast.walk(ast.parse(expr, mode="eval"))
                   if isinstance(n, ast.Name) and n.id not in _BUILTINS
                   and n.id not in CONSTANTS})


def _bind(names: list[str], spaces: dict[str, tuple[str, ...]], what: str) -> dict[str, str]:
    """Each name -> ``space.name`` for the first namespace (in ``spaces`` order) that has it."""
    out = {}
    for n in names:
        for space, fields in spaces.items():
            if n in fields:
                out[n] = f"{space}.{n}"
                break
        else:
            raise ValueError(f"{what}: {n!r} is not a state, an algebra result, a parameter, "
                             f"a derived constant or a flag ({', '.join(spaces)})")
    return out


def _subst(expr: str, binding: dict[str, str]) -> str:
    class T(ast.NodeTransformer):
        def visit_Name(self, node: ast.Name) -> Any:  # noqa: N802 (ast's API)
            if node.id in binding:
                return ast.parse(binding[node.id], mode="eval").body
            return node
    return ast.unparse(T().visit(ast.parse(expr, mode="eval")))


def _rows_tuple(typ: str, names: list[str], start: str, bools: tuple[str, ...] = ()) -> str:
    parts = []
    for k, n in enumerate(names):
        ref = f"W[{start} + {k}, j]"
        parts.append(f"{ref} != 0.0" if n in bools else ref)
    return f"{typ}(" + ", ".join(parts) + ")"


def _active(cond: str, fl_values: dict[str, Any] | None) -> bool:
    """Whether a hold condition can be true in a variant (``fl_values``: its flags; None: any
    variant). A structural flag that is false in the variant drops out of the generated code."""
    if fl_values is None:
        return True
    if cond == "stuck_m":  # a static-friction site exists (model.actuator, sim.kernel._site_on)
        return bool(fl_values["static_m"] and not fl_values["rigid"])
    if cond == "stuck_L":
        return bool(fl_values["static_L"] or (fl_values["rigid"] and fl_values["hybrid"]))
    return bool(fl_values[cond]) if cond in fl_values else True


def source(states: tuple = STATES, variant: int | None = None) -> str:
    """The generated module's source (the ``states`` table may be another one: the tests build
    a kernel with an extra state from it). ``variant``: the state equations' holds written for
    that variant only (its structural flags known: a condition that cannot hold is left out,
    so the paper's EMA compiles exactly as before actuator descriptions)."""
    fl_values = None
    if variant is not None:
        fl_values = dict(zip(actuator.FLAGS, actuator.flags_of(int(variant)),
                             strict=True))
    st_names = [s.name for s in states]
    lines = [
        f"S_PARAM, S_DERIVED, S_MEMORY = {START['param']}, {START['derived']}, "
        f"{START['memory']}",
        f"S_STATE, S_ACC, S_INPUT, S_REC = {START['state']}, {START['acc']}, "
        f"{START['input']}, {START['rec']}",
        "",
        "def lane_params(W, j):",
        "    return " + _rows_tuple("Lane", list(LANE_FIELDS), "S_PARAM", BOOL_LANE),
        "",
        "def load_x(W, j):",
        "    return " + _rows_tuple("X", st_names, "S_STATE"),
        "",
        "def store_x(W, j, x):",
        *(f"    W[S_STATE + {k}, j] = x.{n}" for k, n in enumerate(st_names)),
        "",
        "def load_mem(W, j):",
        "    return " + _rows_tuple("Mem", [m for m, _ in MEMORY], "S_MEMORY"),
        "",
        "def store_mem(W, j, mem):",
        *(f"    W[S_MEMORY + {k}, j] = mem.{n}" for k, (n, _) in enumerate(MEMORY)),
        "",
        "def load_acc(W, j):",
        "    return " + _rows_tuple("Acc", [a.name for a in ACCUMULATORS], "S_ACC"),
        "",
        "def store_acc(W, j, acc):",
        *(f"    W[S_ACC + {k}, j] = acc.{a.name}" for k, a in enumerate(ACCUMULATORS)),
        "",
        "def load_inp(W, j):",
        "    return " + _rows_tuple("Inp", [i for i, _ in INPUTS], "S_INPUT"),
        "",
        "def init_acc(W, j):",
        *(f"    W[S_ACC + {k}, j] = {a.init!r}".replace("inf", "_INF").replace("nan", "_NAN")
          for k, a in enumerate(ACCUMULATORS)),
        "",
        "def init_x(W, j, x0):",
        *(f"    W[S_STATE + {k}, j] = W[x0 + {k}, j]" for k in range(len(st_names))),
        "",
    ]
    # one state replaced (x with <name> = v)
    for s in states:
        fields = ", ".join("v" if o.name == s.name else f"x.{o.name}" for o in states)
        lines += [f"def set_{s.name}(x, v):", f"    return X({fields})", ""]
    # RK4: a stage's state, and the step's combination, over the rk4 states the variant has
    # (the others kept: a state whose element is absent takes no part)
    def integrated(s: Any) -> bool:
        return s.kind == "rk4" and (fl_values is None
                                    or all(bool(fl_values[f]) for f in s.active))

    stage = ", ".join(f"x.{s.name} + hh * k.{s.name}" if integrated(s) else f"x.{s.name}"
                      for s in states)
    lines += ["def rk4_stage(x, hh, k):", f"    return X({stage})", ""]
    comb = ", ".join(
        f"x.{s.name} + h6 * (k1.{s.name} + 2.0 * k2.{s.name} + 2.0 * k3.{s.name} + k4.{s.name})"
        if integrated(s) else f"x.{s.name}" for s in states)
    lines += ["def rk4_combine(x, h6, k1, k2, k3, k4):", f"    return X({comb})", ""]
    # the state equations, their arguments bound by name
    # (a structural flag is read from the variant, a compile-time constant, before the
    # parameter of the same name)
    spaces = {"x": tuple(st_names), "alg": actuator.ALG, "fl": actuator.FLAGS,
              "prm": LANE_FIELDS}
    calls = {}
    for s in states:
        if not integrated(s):
            continue
        args = list(inspect.signature(s.rate.py_func if hasattr(s.rate, "py_func")
                                      else s.rate).parameters)
        b = _bind(args, spaces, f"the rate of state {s.name}")
        calls[s.name] = f"_rate_{s.name}(" + ", ".join(b[a] for a in args) + ")"
    order = [n for n in RATE_ORDER if n in calls] + [n for n in calls if n not in RATE_ORDER]
    held = []
    for s in states:
        if s.name not in calls:
            held.append("0.0")
            continue
        expr = f"d_{s.name}"
        conds = [c for c in s.hold if _active(c, fl_values)]
        if conds:
            b = _bind(conds, spaces, f"the hold of {s.name}")
            expr = f"(0.0 if ({' or '.join(b[c] for c in conds)}) else {expr})"
        held.append(expr)
    lines += ["def rates(x, alg, prm, fl):",
              *(f"    d_{n} = {calls[n]}" for n in order),
              "    return X(" + ", ".join(held) + ")", ""]
    # the metric accumulators
    acc_spaces = {"acc": tuple(a.name for a in ACCUMULATORS), "st": STEP}
    upd = []
    for a in ACCUMULATORS:
        names = _names_in(a.update)
        own = {a.name: f"acc.{a.name}"}
        b = _bind([n for n in names if n != a.name], {"st": STEP}, f"accumulator {a.name}")
        upd.append(_subst(a.update, {**own, **b}))
    del acc_spaces
    lines += ["def accumulate(acc, st):", "    return Acc(" + ", ".join(upd) + ")", ""]
    # the recorded signals
    rec_spaces = {"x": tuple(st_names), "inp": tuple(i for i, _ in INPUTS), "out": OUT,
                  "prm": LANE_FIELDS}
    lines.append("def record(W, j, x, inp, out, prm):")
    for k, c in enumerate(SIGNALS):
        b = _bind(_names_in(c.value), rec_spaces, f"signal {c.name}")
        lines.append(f"    W[S_REC + {k}, j] = {_subst(c.value, b)}")
    return "\n".join(lines) + "\n"


def build(states: tuple = STATES) -> dict[str, Any]:
    """Compile the generated module (:func:`source`) -> its namespace: the compiled functions
    (inlined into the kernel) by name."""
    import numpy as np

    x_type = X if states is STATES else namedtuple("X", [s.name for s in states])
    ns: dict[str, Any] = {"Lane": Lane, "X": x_type,
                          "Mem": Mem, "Acc": Acc, "Inp": Inp, "_INF": np.inf, "_NAN": np.nan,
                          "literally": literally, "flags_nb": actuator.flags_nb, **CONSTANTS}
    for s in states:
        if s.kind == "rk4":
            ns[f"_rate_{s.name}"] = s.rate
    code = source(states)
    exec(compile(code, "<ema_cli.sim.layout: generated>", "exec"), ns)  # noqa: S102
    jit = njit(forceinline=True, error_model="numpy")
    out = {name: jit(ns[name]) for name in
           ("lane_params", "load_x", "store_x", "load_mem", "store_mem", "load_acc",
            "store_acc", "load_inp", "init_acc", "init_x", "rk4_stage", "rk4_combine", "rates",
            "accumulate", "record", *(f"set_{s.name}" for s in states))}
    out["X"] = ns["X"]
    out["source"] = code
    return out


def _rates_for(variant: int | None, states: tuple = STATES) -> Any:
    """The compiled state equations of ``variant`` (None: of any variant), generated once."""
    key = (variant, states)
    if key not in _RATES:
        import numpy as np

        ns: dict[str, Any] = {"X": X if states is STATES else
                              namedtuple("X", [s.name for s in states]), "_INF": np.inf}
        for s in states:
            if s.kind == "rk4":
                ns[f"_rate_{s.name}"] = s.rate
        code = source(states, variant)
        exec(compile(code, f"<ema_cli.sim.layout: variant {variant}>", "exec"), ns)  # noqa: S102
        jit = njit(forceinline=True, error_model="numpy")
        _RATES[key] = tuple(jit(ns[n]) for n in ("rates", "rk4_stage", "rk4_combine"))
    return _RATES[key]


_RATES: dict[tuple[int | None, tuple], Any] = {}


def variant_rates(x: Any, alg: Any, prm: Any, variant: int) -> Any:
    """The rates of the ``rk4`` states (:class:`X`) for the kernel's ``variant``: the generated
    state equations of that variant (compiled once per variant; plain Python without the JIT)."""
    return _rates_for(int(variant))[0](x, alg, prm, actuator.flags_nb(variant))


@overload(variant_rates, prefer_literal=True,
          jit_options={"forceinline": True, "fastmath": {"contract"}, "error_model": "numpy"})
def _variant_rates_ol(x, alg, prm, variant):  # noqa: ANN001, ANN202 (numba's overload API)
    from numba.core import types

    code = variant.literal_value if isinstance(variant, types.IntegerLiteral) else None
    fn = _rates_for(code)[0]
    flags = actuator.flags_nb

    def impl(x, alg, prm, variant):  # noqa: ANN001, ANN202 (numba's overload)
        return fn(x, alg, prm, flags(variant))
    return impl


def variant_stage(x: Any, hh: float, k: Any, variant: int) -> Any:
    """An RK4 stage's state ``x + hh*k`` over the states ``variant`` integrates (the others
    kept; plain Python without the JIT)."""
    return _rates_for(int(variant))[1](x, hh, k)


def variant_combine(x: Any, h6: float, k1: Any, k2: Any, k3: Any, k4: Any, variant: int) -> Any:
    """The RK4 step's combination ``x + h6*(k1 + 2 k2 + 2 k3 + k4)`` over the states
    ``variant`` integrates (the others kept)."""
    return _rates_for(int(variant))[2](x, h6, k1, k2, k3, k4)


def _literal(variant: Any) -> int | None:
    from numba.core import types

    return variant.literal_value if isinstance(variant, types.IntegerLiteral) else None


@overload(variant_stage, prefer_literal=True,
          jit_options={"forceinline": True, "error_model": "numpy"})
def _variant_stage_ol(x, hh, k, variant):  # noqa: ANN001, ANN202 (numba's overload API)
    fn = _rates_for(_literal(variant))[1]

    def impl(x, hh, k, variant):  # noqa: ANN001, ANN202 (numba's overload)
        return fn(x, hh, k)
    return impl


@overload(variant_combine, prefer_literal=True,
          jit_options={"forceinline": True, "error_model": "numpy"})
def _variant_combine_ol(x, h6, k1, k2, k3, k4, variant):  # noqa: ANN001, ANN202 (numba's API)
    fn = _rates_for(_literal(variant))[2]

    def impl(x, h6, k1, k2, k3, k4, variant):  # noqa: ANN001, ANN202 (numba's overload)
        return fn(x, h6, k1, k2, k3, k4)
    return impl


_BUILT = build()
lane_params = _BUILT["lane_params"]
load_x = _BUILT["load_x"]
store_x = _BUILT["store_x"]
load_mem = _BUILT["load_mem"]
store_mem = _BUILT["store_mem"]
load_acc = _BUILT["load_acc"]
store_acc = _BUILT["store_acc"]
load_inp = _BUILT["load_inp"]
init_acc = _BUILT["init_acc"]
init_x = _BUILT["init_x"]
rk4_stage = _BUILT["rk4_stage"]
rk4_combine = _BUILT["rk4_combine"]
rates = _BUILT["rates"]
accumulate = _BUILT["accumulate"]
record = _BUILT["record"]
set_theta_m = _BUILT["set_theta_m"]
set_w_m = _BUILT["set_w_m"]
set_i = _BUILT["set_i"]
set_theta_L = _BUILT["set_theta_L"]
set_w_L = _BUILT["set_w_L"]
set_z = _BUILT["set_z"]
set_xI = _BUILT["set_xI"]
set_f_amp = _BUILT["set_f_amp"]
set_z_L = _BUILT["set_z_L"]
set_f_t = _BUILT["set_f_t"]
set_th_w = _BUILT["set_th_w"]
set_th_h = _BUILT["set_th_h"]
