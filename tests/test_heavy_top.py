"""The heavy top on se(3)* (the compact form of the dual-number pairs): its equations against the
textbook form, the integrals of the exact flow (DOP853), order 2 of IsoMP, the Casimirs to
rounding over a long run, the energy bounded without drift, parameters and errors."""

from __future__ import annotations

import numpy as np
import pytest

import isoflow as iso
from helpers import loglog_slope

TOPS = ("lagrange", "kovalevskaya", "general")


@pytest.mark.parametrize("top", TOPS)
def test_vector_field_is_the_textbook_heavy_top(top: str) -> None:
    """Gamma' = Gamma x Omega, M' = M x Omega + mgl Gamma x chi (Marsden and Ratiu), at random
    states, with the model's parameters read back."""
    prob, y0 = iso.models.heavy_top(top, mgl=1.7)
    p = prob.parameters
    inertia, chi, mgl = np.array(p["inertia"]), np.array(p["center"]), p["mgl"]
    assert y0.shape == (2, 3) and np.linalg.norm(y0[0]) == pytest.approx(1.0, abs=1e-15)
    for Y in np.random.default_rng(1).standard_normal((3, 2, 3)):
        G, M = Y
        Om = M / inertia
        f = prob.vector_field(Y)
        np.testing.assert_allclose(f[0], np.cross(G, Om), rtol=0, atol=1e-14)
        np.testing.assert_allclose(f[1], np.cross(M, Om) + mgl * np.cross(G, chi), rtol=0,
                                   atol=1e-14)  # fmt: skip
        H = 0.5 * M @ Om + mgl * chi @ G
        assert prob.hamiltonian(Y) == pytest.approx(H, rel=1e-15)


@pytest.mark.parametrize("top", ["lagrange", "kovalevskaya"])
def test_the_fourth_integral_is_conserved_by_the_exact_flow(top: str) -> None:
    """The Lagrange spin M3 and the Kovalevskaya integral K stay constant along a tight DOP853
    solution (which checks the formula of K and its scaling with mgl / I3)."""
    prob, y0 = iso.models.heavy_top(top, mgl=2.5, inertia=None)
    name = {"lagrange": "M3", "kovalevskaya": "kovalevskaya"}[top]
    ts = np.linspace(0.0, 10.0, 6)
    ys = iso.reference_solution(prob, y0, ts)
    K = prob.invariants[name](ys)
    assert np.max(np.abs(K - K[0])) <= 1e-10 * max(1.0, abs(K[0]))
    assert float(np.max(np.abs(ys[-1] - y0))) > 0.1  # the top moved
    # K is not conserved by a non-Kovalevskaya top: the check can fail
    other, z0 = iso.models.heavy_top("general")
    zs = iso.reference_solution(other, z0, ts)
    w1, w2 = zs[:, 1, 0], zs[:, 1, 1]
    if top == "kovalevskaya":
        Kz = (w1**2 - w2**2 - zs[:, 0, 0]) ** 2 + (2 * w1 * w2 - zs[:, 0, 1]) ** 2
        assert np.max(np.abs(Kz - Kz[0])) > 1e-2


@pytest.mark.parametrize("top", TOPS)
def test_isomp_is_second_order_against_dop853(top: str) -> None:
    prob, y0 = iso.models.heavy_top(top)
    T = 2.0
    ref = iso.reference_solution(prob, y0, [T])[0]
    hs = np.array([0.04, 0.02, 0.01, 0.005])
    errs = []
    for h in hs:
        sol = iso.solve(prob, iso.IsoMP(), y0, dt=float(h), t1=T, save_every=10**6)
        assert sol.stats.runner.startswith("compiled, se(3) pairs")
        errs.append(float(np.max(np.abs(sol.ys[-1] - ref))))
    assert min(errs) > 1e-8  # far above the reference's error
    assert loglog_slope(hs, np.array(errs)) == pytest.approx(2.0, abs=0.05)


@pytest.mark.parametrize("top", TOPS)
def test_casimirs_at_rounding_and_energy_bounded_over_a_long_run(top: str) -> None:
    """10^5 steps: |Gamma|^2 and M.Gamma within 10^5 roundings of their scale (they drift only
    by the solver's rounding, a random walk, measured ~1e-12), the energy's error bounded and
    not growing (the second half varies no more than the first), M3 exactly (a linear
    invariant of IsoMP)."""
    prob, y0 = iso.models.heavy_top(top)
    n = 100_000
    sol = iso.solve(prob, iso.IsoMP(), y0, dt=0.01, n_steps=n, save_every=100)
    d = sol.diagnostics
    assert float(d.casimir_drift) <= n * np.finfo(float).eps  # 2.2e-11
    H = d.hamiltonian
    dev = np.abs(H - H[0]) / abs(H[0])
    half = len(dev) // 2
    assert 1e-8 < float(np.max(dev)) < 1e-3  # O(h^2): visible, small
    assert float(np.max(dev[half:])) <= 1.5 * float(np.max(dev[:half]))  # no drift
    if top == "lagrange":
        assert float(d.invariant_drift["M3"]) == 0.0
    if top == "kovalevskaya":
        K = d.invariants["kovalevskaya"]
        assert float(np.max(np.abs(K - K[0]))) <= 1e-2 * abs(K[0])  # bounded, O(h^2)


def test_parameters_units_and_errors() -> None:
    kw = {"inertia": [2.0, 3.0, 4.0], "center": [0, 0, 2.0], "mgl": 0.5, "M0": [1.0, 0, 0]}
    prob, y0 = iso.models.heavy_top("general", **kw, Gamma0=[0.0, 3.0, 4.0])
    assert prob.parameters == {
        "top": "general", "inertia": [2.0, 3.0, 4.0], "center": [0.0, 0.0, 1.0], "mgl": 0.5
    }  # fmt: skip
    np.testing.assert_array_equal(y0, [[0.0, 0.6, 0.8], [1.0, 0.0, 0.0]])
    assert prob.algebra.name == "(R^3, x) x| R^3"
    cases = [
        ({"top": "spinning"}, iso.ParameterError, "top must be one of lagrange, kovalevskaya"),
        ({"inertia": [1.0, 2.0]}, iso.ShapeError, "inertia must have 3 components"),
        ({"inertia": [1.0, 0.0, 1.0]}, iso.ParameterError, "moments of inertia must be positive"),
        ({"mgl": -1.0}, iso.ParameterError, "mgl must be a number >= 0"),
        ({"Gamma0": [0.0, 0.0, 0.0]}, iso.ParameterError, "Gamma0 must be a nonzero vector"),
        ({"M0": [0.0, np.nan, 1.0]}, iso.NonFiniteError, "heavy_top: M0 must be finite"),
        ({"mgl": np.nan}, iso.NonFiniteError, "heavy_top: mgl must be finite (found NaN or Inf)"),
        ({"inertia": [1.0, 2.0, 3.0]}, iso.ParameterError,
         "a Lagrange top needs I1 == I2 and the centre of mass on e3, got inertia [1.0, 2.0, 3.0], "
         "center [0.0, 0.0, 1.0]"),
        ({"top": "kovalevskaya", "center": [0, 0, 1]}, iso.ParameterError,
         "a Kovalevskaya top needs I1 == I2 == 2 I3"),
    ]  # fmt: skip
    for kw, kind, text in cases:
        with pytest.raises(kind) as err:
            iso.models.heavy_top(**kw)
        assert text in str(err.value) and "\n" not in str(err.value), kw


def test_registry_builds_the_heavy_top() -> None:
    cfg = {"model": "heavy-top", "params": {"top": "kovalevskaya", "M0": [0.1, 0.2, 0.3]},
           "dt": 0.01, "n_steps": 50}  # fmt: skip
    problem, y0, method, kw = iso.registry.build(cfg)
    np.testing.assert_array_equal(y0[1], [0.1, 0.2, 0.3])
    sol = iso.solve(problem, method, y0, **kw, progress=False)
    assert sol.success and "kovalevskaya" in sol.diagnostics.invariant_drift
    with pytest.raises(iso.registry.ConfigError, match="must be one of"):
        iso.registry.build(cfg | {"params": {"top": "euler"}})
