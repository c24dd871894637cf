"""Dissipation and forcing as a Strang split step (issue 21, items 1 and 2).

The exact linear step, the split step's limits (``B = 0`` exact, ``L = 0`` IsoMP bit for bit),
its order, the budgets, the double bracket, the noise (Ornstein–Uhlenbeck) and the errors of bad
input, on the NumPy and the compiled paths.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np
import pytest

import isoflow as iso
from isoflow.sphere import SphereDissipation, basis_matrix, degree_rates

N = 7
TAU = 0.37


def _numpy(problem: iso.IsospectralProblem) -> iso.IsospectralProblem:
    return dataclasses.replace(problem, kernel=None)


def _rates() -> np.ndarray:
    return degree_rates(N, viscosity=0.3, hyperviscosity=(0.01, 2), drag=0.1)


def test_linear_step_decays_every_harmonic_exactly() -> None:
    """``exp(tau L) T_lm = exp(-tau c_l) T_lm`` for every ``(l, m)``, in NumPy and in the
    compiled per-diagonal kernel (both diagonals parities, odd and even lengths)."""
    from isoflow.sphere.compiled import dissipate

    c = _rates()
    part = SphereDissipation(N, c)
    flow = part.compiled([TAU], iso.algebras.su(N))
    worst = 0.0
    for deg in range(1, N):
        for m in range(-deg, deg + 1):
            T = 1j * basis_matrix(N, deg, m)
            exact = np.exp(-TAU * c[deg]) * T
            W = T.copy()
            dissipate(W, flow.data[0], flow.offe, flow.offo)
            worst = max(worst, float(np.abs(part.flow(T, TAU) - exact).max()))
            worst = max(worst, float(np.abs(W - exact).max()))
    assert worst < 5e-15


@pytest.mark.parametrize("k", [*range(14), 31, 64])
def test_packed_symmetric_product_matches_the_dense_product(k: int) -> None:
    """The per-diagonal kernel's product (rows in pairs, then a last odd row; the inner
    products split by the parity of ``j``) against ``M @ x`` for even and odd sizes, the
    matrix stored at an offset inside a larger buffer, and ``y`` overwritten whatever it
    held."""
    from isoflow.sphere.compiled import _symmetric_product

    rng = np.random.default_rng(k)
    M = rng.standard_normal((k, k))
    M = M + M.T
    packed = M[np.triu_indices(k)]
    off = 5
    P = np.concatenate([np.full(off, np.nan), packed, np.full(3, np.nan)])
    xr, xi = rng.standard_normal(k), rng.standard_normal(k)
    yr, yi = np.full(k, np.nan), np.full(k, np.nan)
    _symmetric_product(P, off, k, xr, xi, yr, yi)
    scale = max(1.0, float(np.abs(M).sum(axis=1).max(initial=0.0)) * 3)
    assert np.abs(yr - M @ xr).max(initial=0.0) <= 4 * k * 2.2e-16 * scale
    assert np.abs(yi - M @ xi).max(initial=0.0) <= 4 * k * 2.2e-16 * scale


def test_per_diagonal_kernel_matches_the_numpy_flow_at_moderate_n() -> None:
    """At ``N = 41`` (folded blocks of up to 21 rows, even and odd) the compiled half step
    equals :meth:`SphereDissipation.flow` to rounding."""
    from isoflow.sphere.compiled import dissipate

    n = 41
    part = SphereDissipation(n, degree_rates(n, viscosity=0.3, hyperviscosity=(0.01, 2), drag=0.1))
    flow = part.compiled([TAU], iso.algebras.su(n))
    W0 = iso.algebras.su(n).random(seed=3)
    W = W0.copy()
    dissipate(W, flow.data[0], flow.offe, flow.offo)
    expected = part.flow(W0, TAU)
    assert np.abs(W - expected).max() < 1e-14 * np.abs(W0).max()
    assert np.array_equal(W, -W.conj().T)  # skew-Hermitian to the last bit


def _zero_B_problem(forcing: Any) -> tuple[iso.IsospectralProblem, np.ndarray]:
    alg = iso.algebras.su(N)
    prob = iso.IsospectralProblem(
        algebra=alg,
        kernel=iso.ElementwiseLinear(np.zeros((N, N))),
        linear_part=SphereDissipation(N, _rates()),
        forcing=forcing,
    )
    return prob, alg.random(seed=1)


@pytest.mark.parametrize("compiled", [False, True], ids=["numpy", "compiled"])
def test_split_step_with_B_zero_is_the_exact_flow(compiled: bool) -> None:
    """``W(t) = e^{tL} W_0 + int_0^t e^{sL} F ds``: two half steps compose exactly."""
    F = iso.algebras.su(N).random(seed=2)
    prob, W0 = _zero_B_problem(iso.Forcing(F))
    prob = prob if compiled else _numpy(prob)
    h, n = 0.2, 10
    sol = iso.solve(prob, iso.Strang(), W0, dt=h, n_steps=n, save_every=n, progress=False)
    assert ("compiled" in sol.stats.runner) == compiled
    part = prob.linear_part
    assert part is not None
    exact = part.flow(W0, n * h) + part.integral(F, n * h)
    assert float(np.abs(sol.ys[-1] - exact).max()) < 1e-13


@pytest.mark.parametrize("alpha", [0.0, 0.7])
@pytest.mark.parametrize("compiled", [False, True], ids=["numpy", "compiled"])
def test_one_rate_on_every_degree_scales_the_state(compiled: bool, alpha: float) -> None:
    """A linear drag alone (or no rate, with a forcing) is the scaling ``e^{-alpha t}``: with
    ``B = 0`` the split run is ``e^{-alpha t} W_0 + (1 - e^{-alpha t}) / alpha F`` to rounding,
    and no per-diagonal matrices are built for it."""
    F = iso.algebras.su(N).random(seed=6)
    part = SphereDissipation(N, np.full(N, alpha))
    assert part.uniform_rate == alpha
    prob, W0 = _zero_B_problem(iso.Forcing(F))
    prob = dataclasses.replace(prob, linear_part=part)
    prob = prob if compiled else _numpy(prob)
    h, n = 0.2, 10
    sol = iso.solve(prob, iso.Strang(), W0, dt=h, n_steps=n, save_every=n, progress=False)
    assert ("compiled" in sol.stats.runner) == compiled
    t = n * h
    ramp = -np.expm1(-alpha * t) / alpha if alpha else t
    exact = np.exp(-alpha * t) * W0 + ramp * F
    assert float(np.abs(sol.ys[-1] - exact).max()) < 1e-14
    assert not part._packed  # the O(N^3) matrices were never formed


@pytest.mark.parametrize("compiled", [False, True], ids=["numpy", "compiled"])
def test_split_step_without_linear_part_is_isomp_bit_for_bit(compiled: bool) -> None:
    prob, W0 = iso.models.euler_sphere(N=8, seed=3)
    prob = prob if compiled else _numpy(prob)
    a = iso.solve(prob, iso.IsoMP(), W0, dt=0.05, n_steps=15, progress=False)
    b = iso.solve(prob, iso.Strang(), W0, dt=0.05, n_steps=15, progress=False)
    assert b.stats.runner.startswith(a.stats.runner)
    assert a.ys.tobytes() == b.ys.tobytes()


def test_a_failed_split_step_freezes_the_state_before_its_first_half_step() -> None:
    """The first half step changes the state before the solve: a step whose solve then fails
    leaves the state where the step began, on the compiled path as on NumPy's."""
    from helpers import compiled_and_numpy

    prob, W0 = iso.models.euler_sphere(N=8, seed=5, viscosity=0.5, drag=0.2)
    good, _ = compiled_and_numpy(prob, iso.Strang(), W0, 0.05, 3)
    tight = iso.Strang(iso.IsoMP(solver=iso.FixedPoint(max_iter=2)))
    a, b = compiled_and_numpy(prob, tight, good.y, 0.05, 3)
    assert a.failures.step[0] == b.failures.step[0] == 0  # failed on its first step
    assert np.array_equal(a.y, good.y) and np.array_equal(b.y, good.y)


def test_split_step_is_second_order_on_the_viscous_sphere() -> None:
    """Log-log slope of the error at ``t = 1`` against a run with a 64 times smaller step."""
    F = 0.5 * iso.algebras.su(8).random(seed=4)
    prob, W0 = iso.models.euler_sphere(
        N=8, seed=5, viscosity=0.05, hyperviscosity=(1e-3, 2), drag=0.2, forcing=F
    )
    T = 1.0

    def final(n: int) -> np.ndarray:
        sol = iso.solve(prob, iso.Strang(), W0, dt=T / n, n_steps=n, save_every=n, progress=False)
        return sol.ys[-1]

    ref = final(640)
    ns = np.array([10, 20, 40])
    errs = np.array([np.linalg.norm(final(n) - ref) for n in ns])
    slope = -np.polyfit(np.log(ns), np.log(errs), 1)[0]
    assert 1.9 < slope < 2.1, (slope, errs)


def test_energy_budget_closes_to_the_splitting_error() -> None:
    """``E(T) - E(0) = int (injection - dissipation) dt`` for a steady forcing: the residual
    is the splitting and quadrature error, ``O(h^2)`` (a quarter when ``h`` halves)."""
    F = 0.3 * iso.algebras.su(8).random(seed=6)
    prob, W0 = iso.models.euler_sphere(N=8, seed=7, viscosity=0.02, drag=0.1, forcing=F)
    T = 2.0

    def residual(n: int) -> float:
        sol = iso.solve(prob, iso.Strang(), W0, dt=T / n, n_steps=n, progress=False)
        d = sol.diagnostics
        assert d.hamiltonian is not None
        rate = d.observables["energy_injection"] - d.observables["energy_dissipation"]
        gained = float(np.trapezoid(rate, sol.ts))
        return abs(float(d.hamiltonian[-1] - d.hamiltonian[0]) - gained) / abs(gained)

    r1, r2 = residual(40), residual(80)
    assert r1 < 1e-3
    assert 3.0 < r1 / r2 < 5.0


def test_transfer_spectrum_sums_to_zero() -> None:
    """The bracket moves energy between degrees and conserves it."""
    prob, W0 = iso.models.euler_sphere(N=10, seed=8, viscosity=1e-3)
    T = prob.observables["energy_transfer"](W0)
    assert T.shape == (9,)
    assert abs(float(T.sum())) < 1e-12 * float(np.abs(T).max())
    assert float(np.abs(T).max()) > 0


@pytest.mark.parametrize("compiled", [False, True], ids=["numpy", "compiled"])
def test_double_bracket_keeps_the_spectrum_and_dissipates_energy(compiled: bool) -> None:
    prob, W0 = iso.models.euler_sphere(N=8, seed=9, double_bracket=0.5, omega=1.0)
    prob = prob if compiled else _numpy(prob)
    sol = iso.solve(prob, iso.IsoMP(), W0, dt=0.05, n_steps=60, progress=False)
    assert ("compiled" in sol.stats.runner) == compiled
    assert float(np.max(sol.diagnostics.casimir_drift)) < 1e-12
    H = sol.diagnostics.hamiltonian
    assert H is not None
    assert np.all(np.diff(H) < 0)
    assert H[-1] < 0.9 * H[0]
    d = sol.diagnostics.summary()  # -E is the problem's Lyapunov function; enstrophy a Casimir
    assert d["lyapunov_max_decrease"] == 0.0 and d["enstrophy_drift"] < 1e-12
    assert "angular_momentum_z" in sol.diagnostics.observables


def test_a_forced_run_reports_no_drift_for_what_it_changes_by_design() -> None:
    """Spectra, budgets, enstrophy and momentum of a forced dissipative run are observables:
    saved, no drift; the ideal model keeps them as invariants."""
    ideal, W0 = iso.models.euler_sphere(N=8, seed=5)
    prob, _ = iso.models.euler_sphere(N=8, seed=5, viscosity=0.05, drag=0.2, forcing=0.5 * W0)
    assert set(ideal.invariants) == {"enstrophy", "angular_momentum"} and not ideal.observables
    assert not prob.invariants and prob.forced_or_dissipative and not ideal.forced_or_dissipative
    sol = iso.solve(prob, iso.Strang(), W0, dt=0.05, n_steps=10, progress=False)
    d = sol.diagnostics
    assert d.forced_or_dissipative
    assert set(d.observables) == {
        "enstrophy", "angular_momentum", "energy_spectrum", "enstrophy_spectrum",
        "energy_transfer", "energy_dissipation", "enstrophy_dissipation", "energy_injection",
        "enstrophy_injection",
    }  # fmt: skip
    assert d.observables["energy_spectrum"].shape == (11, 7)
    assert set(d.summary()) == {
        "casimir_drift",
        "max_distance",
        "hamiltonian_drift",
        "hamiltonian_relative_drift",
    }


def test_observables_and_invariants_need_distinct_names_and_functions() -> None:
    prob, _ = iso.models.euler_sphere(N=4, seed=1)
    f = prob.invariants["enstrophy"]
    with pytest.raises(iso.ParameterError, match="'enstrophy' named both an invariant and an"):
        dataclasses.replace(prob, observables={"enstrophy": f})
    with pytest.raises(iso.ParameterError, match="observables must map names"):
        dataclasses.replace(prob, observables={"x": 1.0})
    with pytest.raises(iso.ParameterError, match="invariants must be a mapping"):
        dataclasses.replace(prob, invariants=[f])


def test_double_bracket_sign_of_the_energy_rate() -> None:
    """``dE/dt = -(4 pi / N) alpha ||[Psi, W]||^2`` at the initial state (finite difference)."""
    alpha = 0.3
    prob, W0 = iso.models.euler_sphere(N=8, seed=10, double_bracket=alpha)
    plain, _ = iso.models.euler_sphere(N=8, seed=10)
    H = prob.hamiltonian
    assert H is not None
    dW = prob.vector_field(W0) - plain.vector_field(W0)  # the double bracket's tendency
    eps = 1e-6
    rate = (float(H(W0 + eps * dW)) - float(H(W0 - eps * dW))) / (2 * eps)
    P = iso.sphere.solve_poisson(W0)
    C = P @ W0 - W0 @ P
    assert rate == pytest.approx(-4 * np.pi / 8 * alpha * float(np.sum(np.abs(C) ** 2)), rel=1e-6)


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"viscosity": -1e-3}, "viscosity must be >= 0"),
        ({"drag": float("nan")}, "drag must be finite"),
        ({"hyperviscosity": (1e-4, 0.5)}, "hyperviscosity order p must be >= 1"),
        ({"hyperviscosity": 1e-4}, "hyperviscosity must be a pair"),
        ({"double_bracket": -0.1}, "double_bracket must be finite and >= 0"),
    ],
)
def test_bad_dissipation_is_refused_in_one_line(kwargs: dict[str, Any], message: str) -> None:
    with pytest.raises(iso.ParameterError, match=message) as info:
        iso.models.euler_sphere(N=6, **kwargs)
    assert "\n" not in str(info.value)


def test_bad_forcing_is_refused_in_one_line() -> None:
    with pytest.raises(iso.ParameterError, match=r"band l = 6 \+- 1 must lie in 1..N-1 = 1..5"):
        iso.sphere.band_forcing(6, 6, 1)
    with pytest.raises(iso.ParameterError, match="energy_rate must be finite"):
        iso.sphere.band_forcing(6, 2, 1, energy_rate=float("inf"))
    bad = iso.StochasticForcing([3, 4], sigma=[1.0, float("nan")])
    with pytest.raises(iso.NonFiniteError, match="sigma must be finite"):
        iso.models.euler_sphere(N=6, forcing=bad)
    outside = np.ones((6, 6))  # Hermitian, not in su(6)
    with pytest.raises(iso.NotInSpaceError, match="forcing pattern"):
        iso.models.euler_sphere(N=6, forcing=outside)
    with pytest.raises(iso.ParameterError, match="forcing must be None, an \\(6, 6\\) matrix"):
        iso.models.euler_sphere(N=6, forcing="band")
    with pytest.raises(iso.ParameterError, match="rates must be >= 0"):
        iso.ModalLinearPart(np.eye(3)[:, None, :] * 0, [-1.0, 0.0, 0.0])


def test_a_split_problem_needs_a_split_method() -> None:
    prob, W0 = iso.models.euler_sphere(N=6, viscosity=1e-3)
    with pytest.raises(iso.ParameterError, match=r"linear part, which IsoMP does not integrate"):
        iso.solve(prob, iso.IsoMP(), W0, dt=0.1, n_steps=2)


def _orthonormal_modes(alg: iso.algebras.Algebra, r: int) -> np.ndarray:
    """``r`` elements of ``alg`` orthonormal in its pairing (Gram–Schmidt of random ones)."""
    out: list[np.ndarray] = []
    for s in range(r):
        e = np.asarray(alg.random(seed=20 + s))
        for f in out:
            e = e - float(alg.inner(f, e)) * f
        out.append(e / np.sqrt(float(alg.inner(e, e))))
    return np.stack(out)


@pytest.mark.parametrize("compiled", [False, True], ids=["numpy", "compiled"])
def test_a_users_linear_part_and_forcing_go_through_the_same_hook(compiled: bool) -> None:
    """A :class:`~isoflow.ModalLinearPart` in a basis of the user's and a steady forcing on
    so(4) with ``B = 0``: the split step is the exact flow, per mode ``e^{-c t}`` on the modes
    and nothing on the rest of the space."""
    alg = iso.algebras.so(4)
    E = _orthonormal_modes(alg, 3)
    rates = np.array([0.5, 2.0, 0.0])
    part = iso.ModalLinearPart(E, rates)
    F = 0.7 * E[0] + 0.2 * np.asarray(alg.random(seed=30))
    prob = iso.IsospectralProblem(
        algebra=alg,
        kernel=iso.ElementwiseLinear(np.zeros((4, 4))),
        linear_part=part,
        forcing=iso.Forcing(F),
    )
    prob = prob if compiled else _numpy(prob)
    W0 = np.asarray(alg.random(seed=31))
    h, n = 0.1, 20
    sol = iso.solve(prob, iso.Strang(), W0, dt=h, n_steps=n, save_every=n, progress=False)
    assert ("compiled" in sol.stats.runner) == compiled
    t = n * h
    coef = lambda X: np.array([float(alg.inner(e, X)) for e in E])  # noqa: E731
    w0, f = coef(W0), coef(F)
    phi = np.where(rates > 0, -np.expm1(-rates * t) / np.where(rates > 0, rates, 1.0), t)
    w_t = np.exp(-rates * t) * w0 + phi * f
    rest = (W0 - np.tensordot(w0, E, 1)) + t * (F - np.tensordot(f, E, 1))
    exact = np.tensordot(w_t, E, 1) + rest
    assert float(np.abs(sol.ys[-1] - exact).max()) < 1e-13


def test_noise_modes_are_sparse_rows_with_the_dense_modes_values() -> None:
    """A half step's noise modes are sparse rows (a real harmonic lives on two diagonals:
    ``2 (N - |m|)`` entries, ``N`` for ``m = 0``), equal to the dense modes: a forcing band at
    ``N = 512`` took a dense ``N x N`` matrix a mode (a band around ``l = 40`` several GB)."""
    from isoflow.splitting import half_step

    N = 24
    lin = SphereDissipation(N, degree_rates(N, viscosity=1e-3))
    idx = np.arange(0, N * N - 1, 5)
    sparse_rows = lin.mode_patterns(idx)
    assert np.array_equal(sparse_rows.toarray(), lin.modes(idx).reshape(idx.size, -1))
    _, ms = iso.sphere.degree_order(N - 1)
    nnz = np.diff(sparse_rows.indptr)
    assert np.all(nnz <= np.where(ms[idx] == 0, N, 2 * (N - np.abs(ms[idx]))))  # exact 0s go
    part = iso.ModalLinearPart(_orthonormal_modes(iso.algebras.so(4), 3), np.ones(3))
    assert np.array_equal(part.mode_patterns([2, 0]).toarray(), part.modes([2, 0]).reshape(2, -1))
    prob, _ = iso.models.euler_sphere(N=N, seed=1, viscosity=1e-3, forcing_band=(8, 2))
    noise = half_step(prob, 0.05).noise
    assert noise.shape == (sum(2 * deg + 1 for deg in range(6, 11)), N * N)
    assert noise.nnz <= 2 * N * noise.shape[0]


@pytest.mark.parametrize(
    "flow",
    [
        "sphere",
        pytest.param("uniform", marks=pytest.mark.slow),
        pytest.param("modal", marks=pytest.mark.slow),
        pytest.param("none", marks=pytest.mark.slow),
    ],
)
def test_an_ensemble_of_split_steps_runs_on_numba_threads(flow: str) -> None:
    """Members of a split step on two numba threads (the parallel driver) take the steps they
    take one after another, bit for bit, for every kind of compiled flow (the parameters of a
    nested flow record failed to compile in the parallel driver)."""
    if flow == "modal":
        alg = iso.algebras.so(4)
        part = iso.ModalLinearPart(_orthonormal_modes(alg, 3), np.array([0.5, 2.0, 0.0]))
        prob = iso.IsospectralProblem(
            algebra=alg, kernel=iso.ElementwiseLinear(np.ones((4, 4))), linear_part=part
        )
        Y0 = np.stack([np.asarray(alg.random(seed=s)) for s in range(3)])
    else:
        kw = {
            "sphere": {"viscosity": 1e-3, "forcing_band": (4, 1)},
            "uniform": {"drag": 0.1},
            "none": {"forcing_band": (4, 1)},
        }[flow]
        prob, W0 = iso.models.euler_sphere(N=10, seed=1, **kw)
        Y0 = np.stack([W0, prob.algebra.project(1.1 * W0), prob.algebra.project(0.9 * W0)])
    runs = [
        iso.solve(
            prob,
            iso.Strang(),
            Y0,
            dt=0.02,
            n_steps=6,
            progress=False,
            threads={"blas": 1, "numba": k},
        )
        for k in (1, 2)
    ]
    assert [r.stats.threads["numba"] for r in runs] == [1, 2]
    assert all("compiled" in r.stats.runner for r in runs)
    assert runs[0].ys.tobytes() == runs[1].ys.tobytes()


@pytest.mark.parametrize("model", ["euler", "qg", "mhd"])
def test_saved_diagnostics_do_not_depend_on_how_the_states_are_batched(model: str) -> None:
    """The diagnostics of saved states (spectra, budgets, transfer, zonal wind, angular
    momentum) are computed on the batches a run's flushes cut, which vary from run to run:
    each state's values must not depend on the batch (identical runs gave result files that
    differed in the last bit of these series)."""
    from isoflow.diagnostics import series

    if model == "euler":
        prob, W0 = iso.models.euler_sphere(N=20, seed=1, viscosity=1e-3, forcing_band=(4, 1))
    elif model == "qg":
        prob, W0 = iso.models.qg_sphere(N=20, seed=1, lamb=2.0, viscosity=1e-3)
    else:
        prob, W0 = iso.models.mhd_sphere(N=12, seed=1)
    method = iso.Strang() if prob.linear_part is not None else iso.IsoMP()
    ys = iso.solve(prob, method, W0, dt=0.01, n_steps=40, progress=False).ys
    whole = series(prob, ys)
    assert any(k.startswith("observables/") or k.startswith("invariants/") for k in whole)
    for size in (1, 3, 8, 13):
        parts = [series(prob, ys[i : i + size]) for i in range(0, len(ys), size)]
        for key, value in whole.items():
            got = np.concatenate([p[key] for p in parts])
            assert got.tobytes() == value.tobytes(), (key, size)


@pytest.mark.parametrize("compiled", [False, True], ids=["numpy", "compiled"])
def test_a_time_dependent_forcing_is_second_order(compiled: bool) -> None:
    """``F(t) = cos(3t) F_0`` with drag on the sphere and ``B = 0``: the error of the split step
    against the exact solution falls as ``h^2`` (amplitudes at the half steps' midpoints)."""
    alpha = 0.4
    F0 = iso.algebras.su(N).random(seed=11)
    forcing = iso.Forcing(F0, amplitude=lambda t: np.cos(3.0 * t))
    prob = iso.IsospectralProblem(
        algebra=iso.algebras.su(N),
        kernel=iso.ElementwiseLinear(np.zeros((N, N))),
        linear_part=SphereDissipation(N, np.full(N, alpha)),
        forcing=forcing,
    )
    prob = prob if compiled else _numpy(prob)
    W0 = iso.algebras.su(N).random(seed=12)
    T = 1.0
    # w' = -alpha w + cos(3t) f: w(T) = e^{-aT} w0 + int_0^T e^{-a(T-s)} cos(3s) ds f
    g = (alpha * np.cos(3 * T) + 3 * np.sin(3 * T) - alpha * np.exp(-alpha * T)) / (alpha**2 + 9)
    exact = np.exp(-alpha * T) * W0 + g * F0

    def error(n: int) -> float:
        sol = iso.solve(prob, iso.Strang(), W0, dt=T / n, n_steps=n, save_every=n, progress=False)
        assert ("compiled" in sol.stats.runner) == compiled
        return float(np.abs(sol.ys[-1] - exact).max())

    e1, e2 = error(20), error(40)
    assert 3.6 < e1 / e2 < 4.4


def test_ornstein_uhlenbeck_mean_energy_tends_to_eps_over_two_alpha() -> None:
    """Bracket off, drag only, white noise on every mode of su(4) (``l = 1..3``): each
    coefficient is an Ornstein–Uhlenbeck process, and the split step adds its exact increment,
    so the ensemble mean energy is :math:`\\frac{\\varepsilon}{2\\alpha}(1 - e^{-2\\alpha t})`
    at every save for any step size, tending to :math:`\\varepsilon/(2\\alpha)`.

    200 members (noise seed 11, member ``m`` keyed by ``(11, m)``), ``alpha = 0.5``,
    ``eps = 0.3``, ``h = 0.2``, ``T = 8``: the mean at each of the 8 saves lies within 4
    standard errors of the ensemble (each about 0.01), and the last standard error is below
    5 % of the limit, so a wrong factor in the noise amplitude (e.g. ``sqrt 2``) fails by far.
    """
    n, members, alpha, eps = 4, 200, 0.5, 0.3
    rates = degree_rates(n, viscosity=0.0, hyperviscosity=None, drag=alpha)
    prob = iso.IsospectralProblem(
        algebra=iso.algebras.su(n),
        B=lambda W: np.zeros_like(W),
        hamiltonian=iso.sphere.energy,
        linear_part=SphereDissipation(n, rates),
        forcing=iso.sphere.band_forcing(n, 2, 1, energy_rate=eps, seed=11),
    )
    W0 = np.zeros((members, n, n), dtype=complex)
    sol = iso.solve(prob, iso.Strang(), W0, dt=0.2, n_steps=40, save_every=5, progress=False)
    E = np.asarray(sol.diagnostics.hamiltonian)  # (saves, members)
    mean = E.mean(axis=1)[1:]
    sem = E.std(axis=1, ddof=1)[1:] / np.sqrt(members)
    limit = eps / (2 * alpha)
    expected = limit * (1 - np.exp(-2 * alpha * sol.ts[1:]))
    assert np.all(np.abs(mean - expected) <= 4 * sem), (mean - expected) / sem
    assert sem[-1] < 0.05 * limit
    assert abs(mean[-1] - limit) <= 4 * sem[-1] + limit * np.exp(-2 * alpha * sol.ts[-1])


def test_split_step_on_the_planar_layout_matches_the_numpy_path(monkeypatch) -> None:
    """Large complex states run IsoMP in real planes on the BLAS layout (from
    ``PLANAR_MIN_N``, lowered here to reach it at N = 40); the split step takes the same
    specialization, not the complex tiles, and agrees with the NumPy path to rounding."""
    from isoflow._compiled import dense, dense_planar
    from isoflow._compiled.runner import compiled_runner
    from isoflow._compiled.stages import split

    monkeypatch.setattr(dense, "PLANAR_MIN_N", 2)
    n = 40
    F = 0.1 * iso.sphere.from_coefficients(
        iso.sphere.to_coefficients(iso.algebras.su(n).random(seed=2), lmax=4), n
    )
    prob, W0 = iso.models.euler_sphere(N=n, seed=1, viscosity=1e-3, drag=0.01, forcing=F)
    runner = compiled_runner(prob, iso.Strang(), W0, 0.01)
    assert runner is not None and runner.layout.record.planar
    assert runner.impl.iterate is dense_planar.iterate
    assert runner.impl.finish is split.finish_planar
    opts = {"dt": 0.01, "n_steps": 6, "progress": False}
    a = iso.solve(prob, iso.Strang(), W0, **opts)
    b = iso.solve(_numpy(prob), iso.Strang(), W0, **opts)
    assert "real planes" in a.stats.runner and "Strang split" in a.stats.runner
    assert float(np.abs(a.ys[-1] - b.ys[-1]).max()) < 1e-13 * float(np.abs(b.ys[-1]).max())
