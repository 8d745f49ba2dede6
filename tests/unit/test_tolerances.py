"""Tolerance files (``ema_cli.production.tolerances``): every bad file is one line naming the
key; the sampler is batch-invariant and seeded, each marginal follows its law, the copula gives
the asked correlation; the box, the nominal unit and the snapshot against hand values."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from scipy import stats

from ema_cli.config.loader import load_config, resolve_run
from ema_cli.errors import EmaError
from ema_cli.production.laws import Z_MAX
from ema_cli.production.tolerances import load_tolerances

ROOT = Path(__file__).resolve().parents[2]
N = {"dist": "normal", "mean": 590, "sd": 15}
U = {"dist": "uniform", "low": 0.0005, "high": 0.002}
KT = {"dist": "truncnormal", "mean": 0.08, "sd": 0.002, "low": 0.075, "high": 0.085}
FC = {"dist": "lognormal", "median": 0.02, "sigma": 0.2}
DZ = {"dist": "triangular", "low": 0, "mode": 0.001, "high": 0.004}
FULL = {"tolerances": {"plant.kL": N, "plant.alpha": U, "plant.Kt": KT, "plant.Fc": FC,
                       "nonlinearities.deadzone1": DZ},
        "correlation": {"plant.kL, plant.alpha": -0.3},
        "worst_case": {"k": 3}}
"""The brief's example, with the triangular law on deadzone1 (the amplifier dead zone, V):
on deadzone2 it would set alpha together with plant.alpha, which is refused."""


def _error(source: Any, *, contains: tuple[str, ...]) -> str:
    """The one-line EmaError ``load_tolerances(source)`` raises, holding every ``contains``."""
    with pytest.raises(EmaError) as ei:
        load_tolerances(source)
    msg = ei.value.message
    assert "\n" not in msg and ei.value.exit_code == 2, msg
    for part in contains:
        assert part in msg, (part, msg)
    return msg


def _tol(**laws: Any) -> dict[str, Any]:
    return {"tolerances": {k.replace("__", "."): v for k, v in laws.items()}}


# ------------------------------------------------------------------------- bad files


BAD: dict[str, tuple[dict[str, Any], tuple[str, ...]]] = {
    "unknown plant parameter": (_tol(plant__kLL=N),
                                ("dict: tolerances.plant.kLL:", "unknown model parameter",
                                 "`ema params`")),
    "unknown section": (_tol(foo__kL=N), ("tolerances.foo.kL:", "plant.NAME",
                                          "nonlinearities.NAME", "`ema locations`")),
    "bare parameter name": (_tol(kL=N), ("tolerances.kL:", "plant.kL")),
    "unknown nonlinearity": (_tol(nonlinearities__deadzone9=U),
                             ("tolerances.nonlinearities.deadzone9:", "deadzone2",
                              "`ema locations`")),
    "a switch": (_tol(plant__friction=U), ("tolerances.plant.friction:", "switch")),
    "not a number": (_tol(plant__kL={"dist": "normal", "mean": "abc", "sd": 1}),
                     ("tolerances.plant.kL.mean:", "valid number")),
    "a boolean": (_tol(plant__kL={"dist": "normal", "mean": True, "sd": 1}),
                  ("tolerances.plant.kL.mean:", "boolean")),
    "NaN": (_tol(plant__kL={"dist": "normal", "mean": float("nan"), "sd": 1}),
            ("tolerances.plant.kL.mean:", "finite")),
    "negative sd": (_tol(plant__kL={"dist": "normal", "mean": 590, "sd": -1}),
                    ("tolerances.plant.kL.sd:", "greater than 0")),
    "zero sd": (_tol(plant__Kt={**KT, "sd": 0}), ("tolerances.plant.Kt.sd:", "greater than 0")),
    "low = high": (_tol(plant__alpha={**U, "low": 0.002}),
                   ("tolerances.plant.alpha:", "low (0.002) must be below high (0.002)")),
    "low > high, truncnormal": (_tol(plant__Kt={**KT, "low": 0.09}),
                                ("tolerances.plant.Kt:", "must be below high")),
    "mode outside": (_tol(nonlinearities__deadzone1={**DZ, "mode": 0.005}),
                     ("tolerances.nonlinearities.deadzone1:", "mode (0.005) must lie in")),
    "sigma <= 0": (_tol(plant__Fc={**FC, "sigma": 0}),
                   ("tolerances.plant.Fc.sigma:", "greater than 0")),
    "median <= 0": (_tol(plant__Fc={**FC, "median": -0.02}),
                    ("tolerances.plant.Fc.median:", "greater than 0")),
    "truncnormal without mass": (_tol(plant__Kt={**KT, "sd": 0.001, "low": 0.1, "high": 0.2}),
                                 ("tolerances.plant.Kt:", "less than 1e-06")),
    "missing law": (_tol(plant__kL={"mean": 1}), ("tolerances.plant.kL.dist:", "missing")),
    "unknown law": (_tol(plant__kL={"dist": "gamma"}),
                    ("tolerances.plant.kL.dist:", "unknown law 'gamma'", "truncnormal")),
    "missing field": (_tol(plant__kL={"dist": "normal", "mean": 590}),
                      ("tolerances.plant.kL.sd:", "required")),
    "unknown field": (_tol(plant__kL={**N, "low": 3}), ("tolerances.plant.kL.low:",
                                                        "unknown key")),
    "entry not a mapping": (_tol(plant__kL=3), ("tolerances.plant.kL:", "expected a mapping")),
    "coefficient outside [-1, 1]": (
        {**_tol(plant__kL=N, plant__alpha=U), "correlation": {"plant.kL, plant.alpha": 1.3}},
        ('correlation "plant.kL, plant.alpha"', "outside [-1, 1]")),
    "pair naming a path not in tolerances": (
        {**_tol(plant__kL=N, plant__alpha=U), "correlation": {"plant.kL, plant.Kt": 0.3}},
        ('correlation "plant.kL, plant.Kt"', "'plant.Kt' is not in tolerances")),
    "path paired with itself": (
        {**_tol(plant__kL=N, plant__alpha=U), "correlation": {"plant.kL, plant.kL": 0.3}},
        ('correlation "plant.kL, plant.kL"', "itself")),
    "pair given twice": (
        {**_tol(plant__kL=N, plant__alpha=U),
         "correlation": {"plant.kL, plant.alpha": 0.3, "plant.alpha,plant.kL": 0.2}},
        ('correlation "plant.alpha,plant.kL"', "given twice")),
    "pair of one path": (
        {**_tol(plant__kL=N, plant__alpha=U), "correlation": {"plant.kL": 0.3}},
        ('correlation "plant.kL"', "two tolerance paths")),
    "coefficient not a number": (
        {**_tol(plant__kL=N, plant__alpha=U), "correlation": {"plant.kL, plant.alpha": "x"}},
        ("correlation.plant.kL, plant.alpha:", "valid number")),
    "not positive definite": (
        {**_tol(plant__kL=N, plant__alpha=U, plant__Kt=KT),
         "correlation": {"plant.kL, plant.alpha": 0.9, "plant.kL, plant.Kt": 0.9,
                         "plant.alpha, plant.Kt": -0.9}},
        ("dict: correlation:", "not positive definite", "Cholesky fails")),
    "coefficient 1": (
        {**_tol(plant__kL=N, plant__alpha=U), "correlation": {"plant.kL, plant.alpha": 1.0}},
        ("correlation:", "not positive definite")),
    "empty tolerances": ({"tolerances": {}}, ("dict: tolerances: empty",)),
    "no tolerances": ({}, ("dict: tolerances: missing",)),
    "unknown top-level key": ({**_tol(plant__kL=N), "tolerance": 1},
                              ("dict: tolerance: unknown key",)),
    "uniform below 0 on alpha": (
        _tol(plant__alpha={**U, "low": -0.001}),
        ("tolerances.plant.alpha:", "low = -0.001", "must be >= 0")),
    "normal reaching below 0": (
        _tol(plant__alpha={"dist": "normal", "mean": 0.001, "sd": 0.0002}),
        ("tolerances.plant.alpha:", f"mean - {Z_MAX:.3g} sd", "must be >= 0", "truncnormal")),
    "nonlinearity below 0": (
        _tol(nonlinearities__deadzone2={**U, "low": -0.001}),
        ("tolerances.nonlinearities.deadzone2:", "low = -0.001", ">= 0 in deg")),
    "saturation limit 0": (
        _tol(nonlinearities__saturation3={"dist": "uniform", "low": 0, "high": 30}),
        ("tolerances.nonlinearities.saturation3:", "low = 0", "> 0 A")),
    "a share above 1": (
        _tol(plant__contact_hc={"dist": "uniform", "low": 0.5, "high": 1.2}),
        ("tolerances.plant.contact_hc:", "high = 1.2", "[0, 1]")),
    "one placement twice": (
        _tol(nonlinearities__deadzone2=U, **{"nonlinearities__deadzone@transmission": U}),
        ("tolerances.nonlinearities.deadzone@transmission:", "'nonlinearities.deadzone2'",
         "'alpha'")),
    "a plant value and a nonlinearity on one parameter": (
        _tol(plant__alpha=U, nonlinearities__deadzone2=DZ),
        ("tolerances.nonlinearities.deadzone2:", "'plant.alpha'", "both set", "'alpha'")),
    "box factor out of range": ({**_tol(plant__kL=N), "worst_case": {"k": -1}},
                                ("dict: worst_case.k:", "greater than 0")),
}


@pytest.mark.parametrize("case", list(BAD))
def test_a_bad_file_is_one_line_naming_the_key(case):
    doc, contains = BAD[case]
    _error(doc, contains=contains)


def test_a_missing_file_and_a_yaml_syntax_error_name_the_file(tmp_path):
    _error(tmp_path / "nope.yaml", contains=("tolerance file", "nope.yaml", "does not exist"))
    bad = tmp_path / "bad.yaml"
    bad.write_text("tolerances:\n  plant.kL: {dist: normal, mean: 590, sd: 15\n"
                   "  plant.Kt: 1\n")
    _error(bad, contains=("bad.yaml: YAML syntax error at line 3",))
    bad.write_text("tolerances:\n  plant.kL: {dist: normal, mean: 590, sd: -15}\n")
    _error(bad, contains=(f"{bad}: tolerances.plant.kL.sd:", "greater than 0"))


def test_a_yaml_file_reads_as_its_dict(tmp_path):
    path = tmp_path / "tol.yaml"
    path.write_text("tolerances:\n"
                    "  plant.kL: {dist: normal, mean: 590, sd: 15}\n"
                    "  plant.alpha: {dist: uniform, low: 5e-4, high: 2.0e-3}\n"
                    "correlation:\n"
                    '  "plant.kL, plant.alpha": -0.3\n')
    t = load_tolerances(path)
    assert t.source == str(path) and t.paths == ("plant.kL", "plant.alpha")
    same = load_tolerances(_tol(plant__kL=N, plant__alpha=U)
                           | {"correlation": {"plant.kL, plant.alpha": -0.3}})
    np.testing.assert_array_equal(t.sample(0, 5, 1), same.sample(0, 5, 1))


# ------------------------------------------------------------------------- sampling


@pytest.fixture(scope="module")
def full():
    return load_tolerances(FULL)


@pytest.mark.parametrize("method", ["random", "sobol"])
def test_sampling_does_not_depend_on_the_batches(full, method):
    whole = full.sample(0, 100, 11, method)
    for cuts in ([4], [1, 2, 3, 64], [37, 99]):
        edges = [0, *cuts, 100]
        parts = [full.sample(a, b, 11, method) for a, b in zip(edges, edges[1:], strict=False)]
        np.testing.assert_array_equal(np.vstack(parts), whole)  # exact, bit for bit
    assert full.sample(5, 5, 11, method).shape == (0, 5)
    # larger, uneven batches of the bundled file (numpy and scipy pick other inner loops for
    # long arrays; the values must not notice)
    bundled = load_tolerances(ROOT / "configs" / "tolerances.yaml")
    whole = bundled.sample(0, 3000, 123, method)
    edges = [0, 1, 7, 16, 17, 1000, 1001, 2048, 2999, 3000]
    parts = [bundled.sample(a, b, 123, method) for a, b in zip(edges, edges[1:], strict=False)]
    np.testing.assert_array_equal(np.vstack(parts), whole)


@pytest.mark.parametrize("method", ["random", "sobol"])
def test_the_same_seed_gives_the_same_units_another_seed_others(full, method):
    a = full.sample(0, 50, 3, method)
    np.testing.assert_array_equal(a, full.sample(0, 50, 3, method))
    b = full.sample(0, 50, 4, method)
    assert a.shape == b.shape == (50, 5)
    assert not np.any(np.all(a == b, axis=1))  # no unit repeats under another seed


def test_a_snapshot_reloads_to_the_same_units(full):
    again = load_tolerances(full.to_dict())
    assert again.to_dict() == full.to_dict()
    np.testing.assert_array_equal(again.sample(0, 20, 9), full.sample(0, 20, 9))
    import json
    assert json.loads(json.dumps(full.to_dict())) == full.to_dict()


def _cdfs():
    """The scipy cdf of each law of FULL, in file order."""
    a, b = (0.075 - 0.08) / 0.002, (0.085 - 0.08) / 0.002
    return [stats.norm(590, 15).cdf, stats.uniform(0.0005, 0.0015).cdf,
            stats.truncnorm(a, b, loc=0.08, scale=0.002).cdf,
            stats.lognorm(s=0.2, scale=0.02).cdf, stats.triang(0.25, loc=0, scale=0.004).cdf]


def test_each_marginal_follows_its_law(full):
    # 4000 random units, the copula on (kL, alpha) included: it must not move the marginals.
    # p > 1e-3 at a fixed seed (the KS test of a correct sampler fails with probability 1e-3)
    x = full.sample(0, 4000, 2026)
    for j, cdf in enumerate(_cdfs()):
        p = stats.kstest(x[:, j], cdf).pvalue
        assert p > 1e-3, (full.paths[j], p)
    kt = x[:, 2]
    assert kt.min() >= 0.075 and kt.max() <= 0.085
    # and a law that is not what it claims fails the same test (the test has power)
    assert stats.kstest(x[:, 0], stats.norm(590, 16.5).cdf).pvalue < 1e-3


def test_sobol_means_are_accurate(full):
    x = full.sample(0, 1024, 5, "sobol")
    assert abs(x[:, 0].mean() - 590) / 590 < 1e-3  # the normal law's mean
    # the Sobol' error is far below the random one (sd/sqrt(n) = 0.47 on kL): 0.05 N*m/rad
    assert abs(x[:, 0].mean() - 590) < 0.05
    assert abs(x[:, 1].mean() - 0.00125) / 0.00125 < 1e-3  # the uniform's midpoint


def test_truncnormal_samples_stay_in_their_interval():
    t = load_tolerances(_tol(plant__Kt={**KT, "low": 0.0801, "high": 0.0802}))
    for method in ("random", "sobol"):
        x = t.sample(0, 2000, 1, method)[:, 0]
        assert x.min() >= 0.0801 and x.max() <= 0.0802
    # a one-sided tail interval, 4 sd above the mean, still follows its law
    t = load_tolerances(_tol(plant__Kt={**KT, "low": 0.088, "high": 0.1}))
    x = t.sample(0, 4000, 1)[:, 0]
    assert x.min() >= 0.088 and x.max() <= 0.1
    assert stats.kstest(x, stats.truncnorm(4, 10, loc=0.08, scale=0.002).cdf).pvalue > 1e-3


@pytest.mark.parametrize("rho", [-0.3, 0.6])
def test_the_copula_gives_the_asked_correlation(rho):
    doc = {**_tol(plant__kL=N, plant__Fc=FC, plant__Kt=KT),
           "correlation": {"plant.kL, plant.Fc": rho}}
    x = load_tolerances(doc).sample(0, 4000, 17)
    # normal scores from the ranks: their correlation is the copula's coefficient; the
    # sampling sd of a correlation at n = 4000 is (1 - rho^2)/sqrt(n) < 0.016, 0.05 is > 3 sd
    scores = stats.norm.ppf((stats.rankdata(x, axis=0) - 0.5) / len(x))
    r = np.corrcoef(scores.T)
    assert abs(r[0, 1] - rho) < 0.05
    assert abs(r[0, 2]) < 0.05 and abs(r[1, 2]) < 0.05  # the others stay independent
    spearman = stats.spearmanr(x[:, 0], x[:, 1]).statistic
    assert abs(spearman - 6 / math.pi * math.asin(rho / 2)) < 0.05


def test_bad_sample_arguments_are_refused(full):
    for args, part in (((0, 10, 1, "latin"), "random, sobol"), ((5, 4, 1), "start <= stop"),
                       ((-1, 4, 1), "start <= stop"), ((0, 4, -1), "seed"),
                       ((0, 4, 1.5), "seed"), ((0.5, 4, 1), "start must be an integer")):
        with pytest.raises(EmaError, match=part.replace("(", r"\(")):
            full.sample(*args)


# ------------------------------------------------------------ box, nominal, pairs, describe


def test_box_and_nominal_against_hand_values(full):
    lo, hi = full.box()
    e = math.exp(3 * 0.2)
    np.testing.assert_allclose(lo, [590 - 45, 0.0005, 0.075, 0.02 / e, 0.0], rtol=1e-12)
    np.testing.assert_allclose(hi, [590 + 45, 0.002, 0.085, 0.02 * e, 0.004], rtol=1e-12)
    np.testing.assert_allclose(full.nominal(), [590, 0.00125, 0.08, 0.02, 0.001], rtol=1e-12)
    # truncnormal: mean -+ k sd inside [low, high] when narrower; k from the caller wins
    t = load_tolerances(_tol(plant__Kt={**KT, "sd": 0.001}), k=2)
    assert t.k == 2 and t.box() == (pytest.approx([0.078]), pytest.approx([0.082]))
    # the box never leaves what the parameter can take: a normal share near its bound 1
    t = load_tolerances(_tol(plant__contact_hc={"dist": "normal", "mean": 0.5, "sd": 0.07}),
                        k=7)
    assert t.box()[1][0] == pytest.approx(0.99)
    _error({**_tol(plant__kL=N), "worst_case": {"k": 8}}, contains=("worst_case.k:",))


def test_pairs_describe_and_units(full):
    row = full.sample(0, 1, 0)[0]
    pairs = full.pairs(row)
    assert [p for p, _ in pairs] == list(full.paths)
    assert [v for _, v in pairs] == row.tolist()
    assert full.units == ("N*m/rad", "rad", "N*m/A", "N*m", "V")
    assert full.describe()[0] == "plant.kL: normal, mean 590, sd 15 [N*m/rad]"
    assert full.describe()[4] == ("nonlinearities.deadzone1: triangular, low 0, mode 0.001, "
                                  "high 0.004 [V]")
    with pytest.raises(EmaError, match="5 values"):
        full.pairs([1.0, 2.0])
    assert full.model_parameters() == {"kL": "plant.kL", "alpha": "plant.alpha",
                                       "Kt": "plant.Kt", "Fc": "plant.Fc",
                                       "d1": "nonlinearities.deadzone1"}
    friction = load_tolerances(_tol(nonlinearities__friction1=FC))
    assert friction.model_parameters() == {"friction": "nonlinearities.friction1",
                                           "sigma2": "nonlinearities.friction1"}


def test_the_bundled_file_resolves_at_every_box_corner():
    """configs/tolerances.yaml loads, and its nominal unit and the corners of its box are
    valid run configs: every value goes through ``load_config`` and ``resolve_run``."""
    t = load_tolerances(ROOT / "configs" / "tolerances.yaml")
    assert 5 <= t.d <= 8
    lo, hi = t.box()
    rows = [t.nominal(), lo, hi, *t.sample(0, 8, 0, "sobol")]
    for row in rows:
        cfg = load_config(None, t.pairs(row))
        resolve_run(cfg)
    assert np.all(lo <= t.nominal()) and np.all(t.nominal() <= hi)


@pytest.mark.parametrize("given", [
    {"plant.kL,plant.Kt": 0.4}, {"plant.kL ~ plant.Kt": 0.4}, {"(plant.kL, plant.Kt)": 0.4},
    {"plant.kL": {"plant.Kt": 0.4}}, [["plant.kL", "plant.Kt", 0.4]]])
def test_a_correlation_pair_may_be_written_several_ways(given):
    base = {"plant.kL": {"dist": "normal", "mean": 590, "sd": 15},
            "plant.Kt": {"dist": "uniform", "low": 0.076, "high": 0.084}}
    tol = load_tolerances({"tolerances": base, "correlation": given})
    assert tol.correlations == (("plant.kL", "plant.Kt", 0.4),)
    assert tol.corr[0, 1] == tol.corr[1, 0] == 0.4


@pytest.mark.parametrize(("given", "key"), [
    ([["plant.kL", "plant.Kt"]], "correlation.0"),
    ({"plant.kL": 0.3, "x": {"y": 1}}, "correlation.plant.kL"),
    ({"plant.kL": {"plant.Kt": 1.4}}, "plant.kL, plant.Kt")])
def test_a_malformed_correlation_is_one_line_naming_it(given, key):
    base = {"plant.kL": {"dist": "normal", "mean": 590, "sd": 15},
            "plant.Kt": {"dist": "uniform", "low": 0.076, "high": 0.084}}
    with pytest.raises(EmaError) as exc:
        load_tolerances({"tolerances": base, "correlation": given})
    assert key in str(exc.value) and "\n" not in str(exc.value)
