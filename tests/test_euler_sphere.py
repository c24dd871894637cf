"""The Euler model on the sphere (Zeitlin): B, steady states, continuum limit, Rossby-Haurwitz
waves, conservation under IsoMP, parameters and errors.

Expected values come from independent computations: a dense pseudo-inverse of the Laplacian,
the continuum Euler vector field evaluated on a grid (ducc0 gradients), and the analytic phase
speed of Rossby-Haurwitz waves derived below.
"""

from __future__ import annotations

import importlib

import ducc0
import numpy as np
import pytest

import isoflow as iso
import isoflow.plotting
from isoflow import sphere
from isoflow.sphere._grid import _to_alm


def dense_B(W: np.ndarray, omega: float = 0.0) -> np.ndarray:
    """B(Q) = Delta_N^+ Q / hbar + i Omega J_3 from the dense double-commutator operator."""
    N = W.shape[-1]
    I = np.eye(N)
    L = np.zeros((N * N, N * N), dtype=complex)
    for S in sphere.spin_matrices(N):
        ad = np.kron(S, I) - np.kron(I, S.T)
        L += ad @ ad
    P = (np.linalg.pinv(L) @ W.ravel()).reshape(N, N)
    J3 = np.diag(np.arange(N) - 0.5 * (N - 1))
    return P / sphere.hbar(N) + 1j * omega * J3


def continuum_rhs(c: np.ndarray, lmax: int, omega: float = 0.0) -> np.ndarray:
    r"""Coefficients (degree <= 2 lmax) of the continuum Euler tendency
    :math:`\{\omega + f, \psi\} = \frac{1}{\sin\theta}(q_\theta\psi_\varphi -
    q_\varphi\psi_\theta)`, :math:`\Delta\psi = \omega`, :math:`f = 2\Omega\cos\theta`,
    with the gradients of ducc0 on a Gauss-Legendre grid fine enough to be exact."""
    ls, _ = sphere.degree_order(lmax)
    q = c.copy()
    q[sphere.lm_index(1, 0)] += 2 * omega * np.sqrt(4 * np.pi / 3)  # f = 2 Omega z
    psi = -c / (ls * (ls + 1.0))
    nt = 2 * lmax + 2
    grads = []
    for co in (q, psi):  # ducc0: (d/dtheta, (1/sin theta) d/dphi)
        grads.append(
            ducc0.sht.synthesis_2d_deriv1(
                alm=_to_alm(co[None], lmax), lmax=lmax, geometry="GL", ntheta=nt, nphi=2 * nt
            )
        )
    (qt, qp), (pt, pp) = grads
    return sphere.analyze(qt * pp - qp * pt, 2 * lmax, geometry="GL")


def test_ducc0_gradient_convention() -> None:
    """The gradient components used by continuum_rhs, on f = x = sin(theta) cos(phi)."""
    lmax = 3
    c = np.zeros(sphere.coefficient_count(lmax))
    c[sphere.lm_index(1, 1)] = np.sqrt(4 * np.pi / 3)
    g = ducc0.sht.synthesis_2d_deriv1(alm=_to_alm(c[None], lmax), lmax=lmax, geometry="GL",
                                      ntheta=8, nphi=16)  # fmt: skip
    theta, phi = sphere.grid(8, 16, "GL")
    T, P = np.meshgrid(theta, phi, indexing="ij")
    assert np.max(np.abs(g[0] - np.cos(T) * np.cos(P))) <= 1e-14
    assert np.max(np.abs(g[1] + np.sin(P))) <= 1e-14


# ---- B ---------------------------------------------------------------------------------------


@pytest.mark.parametrize(("N", "omega"), [(2, 0.0), (5, 0.0), (6, 1.3), (9, -0.4)])
def test_kernel_B_is_the_inverse_laplacian_over_hbar(N: int, omega: float) -> None:
    prob, Q0 = iso.models.euler_sphere(N=N, omega=omega, seed=N)
    ref = dense_B(Q0, omega)
    B = prob.B(Q0)
    assert np.max(np.abs(B - ref)) <= 1e-12 * np.max(np.abs(ref))
    # the IsoMP stage lies in u(N): its trace is ignored and B stays in u(N)
    X = Q0 + 0.3j * np.eye(N)
    BX = prob.B(X)
    assert np.max(np.abs(BX - B)) <= 1e-13 * np.max(np.abs(B))
    assert np.max(np.abs(BX + BX.conj().T)) <= 1e-14 * np.max(np.abs(B))
    # batched evaluation agrees member by member
    prob.check_B(np.stack([Q0, 2 * Q0]))


def test_pure_degree_and_zonal_states_are_steady() -> None:
    N = 12
    rng = np.random.default_rng(0)
    prob, _ = iso.models.euler_sphere(N=N, lmax=3)
    for l in (1, 2, 5, N - 1):
        c = np.zeros(N * N - 1)
        sl = slice(sphere.lm_index(l, -l), sphere.lm_index(l, l) + 1)
        c[sl] = rng.standard_normal(2 * l + 1)
        W = sphere.from_coefficients(c, N)
        B = prob.B(W)
        comm = B @ W - W @ B
        assert np.linalg.norm(comm) <= 1e-13 * np.linalg.norm(B) * np.linalg.norm(W)
    for omega in (0.0, 2.0):  # zonal (diagonal) states, with or without rotation
        prob, _ = iso.models.euler_sphere(N=N, omega=omega, lmax=3)
        d = rng.standard_normal(N)
        Q = np.diag(1j * (d - d.mean()))
        B = prob.B(Q)
        assert np.max(np.abs(B @ Q - Q @ B)) <= 1e-14 * np.max(np.abs(B)) * np.max(np.abs(Q))


# ---- the continuum limit -----------------------------------------------------------------------


@pytest.mark.parametrize("omega", [0.0, 0.7])
def test_vector_field_converges_to_the_continuum_euler_equations(omega: float) -> None:
    """(1/hbar)[P, W + F] in coefficients against {omega + f, psi}: second order in 1/N."""
    L0 = 4
    c = np.random.default_rng(3).standard_normal(sphere.coefficient_count(L0))
    ref = continuum_rhs(c, L0, omega)
    k = ref.size
    errs = []
    Ns = (12, 24, 48)
    for N in Ns:
        prob, Q0 = iso.models.euler_sphere(N=N, omega=omega, initial=c)
        q = sphere.to_coefficients(prob.vector_field(Q0))
        assert np.max(np.abs(q[k:]), initial=0.0) <= 1e-12  # no degree above 2 L0, as ref
        errs.append(np.max(np.abs(q[:k] - ref)) / np.max(np.abs(ref)))
    order = -np.polyfit(np.log(Ns), np.log(errs), 1)[0]
    assert 1.9 < order < 2.1, errs
    assert errs[-1] < 2e-3


def haurwitz_speed(l: int, w: float, omega: float) -> float:
    r"""Angular phase speed (eastward) of the Rossby-Haurwitz wave of degree ``l``.

    :math:`\omega = 2w z + \omega'`, :math:`\omega'` of pure degree ``l``: then
    :math:`\psi = -wz - \omega'/(l(l+1))` and :math:`\{z, g\} = -\partial_\varphi g`, so
    :math:`\dot\omega' = \{2(w + \Omega) z + \omega', \psi\} = (2(w+\Omega)/(l(l+1)) - w)
    \,\partial_\varphi\omega'`: a rigid rotation with
    :math:`\nu = w - 2(w+\Omega)/(l(l+1)) = (w(l+2)(l-1) - 2\Omega)/(l(l+1))`
    (Haurwitz 1940, with ``R = l - 1``).
    """
    return (w * (l + 2) * (l - 1) - 2 * omega) / (l * (l + 1))


@pytest.mark.parametrize(
    ("N", "l", "m", "w", "omega"),
    [(12, 4, 3, 0.0, 1.0), (13, 3, 2, 0.5, 0.0), (16, 5, 4, 0.3, 1.5)],
)
def test_rossby_haurwitz_waves_travel_at_the_continuum_speed(
    N: int, l: int, m: int, w: float, omega: float
) -> None:
    """In Zeitlin's model these waves are exact (ad of X_3 is the exact rotation generator),
    so the only error is IsoMP's: second order in h. Its Richardson extrapolation from
    h = 0.02, 0.01 must then give the continuum speed to about 1e-5."""
    nu = haurwitz_speed(l, w, omega)
    c = np.zeros(N * N - 1)
    c[sphere.lm_index(1, 0)] = 2 * w * np.sqrt(4 * np.pi / 3)
    c[sphere.lm_index(l, m)] = 0.8
    c[sphere.lm_index(l, -m)] = -0.5
    prob, Q0 = iso.models.euler_sphere(N=N, omega=omega, initial=c)
    F = iso.models.coriolis_matrix(N, omega)
    a0 = 0.8 + 0.5j  # omega_{l,m} - i omega_{l,-m} ~ e^{-i m nu t}
    speeds = []
    for h in (0.02, 0.01):
        sol = iso.solve(prob, iso.IsoMP(), Q0, dt=h, t1=1.0, save_every=1)
        co = sphere.to_coefficients(sol.ys - F, lmax=l)
        a = co[:, sphere.lm_index(l, m)] - 1j * co[:, sphere.lm_index(l, -m)]
        assert np.max(np.abs(np.abs(a) - abs(a0))) <= 1e-4 * abs(a0)  # rigid, up to O(h^2)
        assert np.max(np.abs(co[:, sphere.lm_index(1, 0)] - c[sphere.lm_index(1, 0)])) <= 1e-13
        phase = np.unwrap(np.angle(a / a0))
        speeds.append(-np.polyfit(sol.ts, phase, 1)[0] / m)
    e1, e2 = speeds[0] - nu, speeds[1] - nu
    assert e1 / e2 == pytest.approx(4.0, rel=0.03)  # IsoMP's O(h^2), nothing else
    extrapolated = (4 * speeds[1] - speeds[0]) / 3
    assert abs(extrapolated - nu) <= 2e-5 * max(abs(nu), 0.1)


# ---- conservation under IsoMP ----------------------------------------------------------------


@pytest.mark.parametrize(
    ("N", "omega", "h", "n_steps"), [(32, 0.0, 0.1, 10_000), (64, 1.0, 0.05, 10_000)]
)
def test_casimirs_at_rounding_over_many_steps(N: int, omega: float, h: float, n_steps: int) -> None:
    """10^4 steps (the compiled BLAS path with the model's compiled Poisson solve)."""
    prob, Q0 = iso.models.euler_sphere(N=N, omega=omega, seed=1)
    sol = iso.solve(prob, iso.IsoMP(), Q0, dt=h, n_steps=n_steps, save_every=n_steps // 4)
    assert sol.stats.runner.startswith("compiled")
    d = sol.diagnostics
    # "to rounding": at most one unit of rounding per step, relative to the invariant's scale
    budget = n_steps * np.finfo(float).eps  # 2.2e-12 for 10^4 steps
    assert d.casimir_drift.max() <= budget  # eigenvalues, relative to ||Q0||
    C = sphere.casimirs(sol.ys)  # int (omega + f)^k, k = 2..6
    lam = np.max(np.abs(sphere.vorticity_levels(Q0)))
    scale = 4 * np.pi * lam ** np.arange(2, 7)
    assert np.max(np.abs(C - C[0]) / scale) <= budget
    assert d.invariant_drift["enstrophy"] <= budget * sphere.enstrophy(Q0)
    key = "angular_momentum" if omega == 0 else "angular_momentum_z"
    assert np.max(d.invariant_drift[key]) <= budget  # the momentum map, to rounding
    assert d.hamiltonian_relative_drift <= 1e-2  # bounded O(h^2), not rounding


def test_energy_error_is_second_order_in_the_step() -> None:
    prob, W0 = iso.models.euler_sphere(N=16, lmax=4, seed=2)
    drifts = []
    for h in (0.1, 0.05, 0.025):
        sol = iso.solve(prob, iso.IsoMP(), W0, dt=h, t1=4.0, save_every=1)
        drifts.append(float(sol.diagnostics.hamiltonian_drift))
    rates = np.log2(np.array(drifts[:-1]) / np.array(drifts[1:]))
    assert np.all(np.abs(rates - 2.0) < 0.25), drifts


# ---- the model's interface ------------------------------------------------------------------


def test_initial_data_kinds_and_parameters() -> None:
    N = 10
    prob, W = iso.models.euler_sphere(N=N, seed=3, lmin=2, lmax=5, rms=0.5)
    c = sphere.to_coefficients(W)
    ls, _ = sphere.degree_order(N - 1)
    assert np.all(np.abs(c[(ls < 2) | (ls > 5)]) <= 1e-14)
    assert sphere.enstrophy(W) == pytest.approx(2 * np.pi * 0.25, rel=1e-12)
    p = prob.parameters
    assert p["N"] == N and p["omega"] == 0.0 and p["hbar"] == sphere.hbar(N)
    assert (p["seed"], p["lmin"], p["lmax"], p["rms"], p["initial"]) == (3, 2, 5, 0.5, "random")
    assert prob.hamiltonian(W) == pytest.approx(0.5 * np.sum(c**2 / (ls * (ls + 1.0))), rel=1e-12)
    # from a function and from coefficients (a batch: an ensemble)
    _, Wf = iso.models.euler_sphere(N=N, initial=lambda t, p: np.sin(t) ** 2 * np.cos(2 * p))
    expected = np.zeros(N * N - 1)
    expected[sphere.lm_index(2, 2)] = np.sqrt(16 * np.pi / 15)  # x^2 - y^2 = sin^2 cos 2phi
    assert np.max(np.abs(sphere.to_coefficients(Wf) - expected)) <= 1e-13
    cs = np.random.default_rng(0).standard_normal((2, 8))
    _, Wb = iso.models.euler_sphere(N=N, initial=cs)
    assert Wb.shape == (2, N, N)
    # the state on a rotating sphere is the absolute vorticity W + F, F ~ T_10
    probr, Q = iso.models.euler_sphere(N=N, omega=2.0, initial=cs[0])
    q = sphere.to_coefficients(Q)
    assert q[sphere.lm_index(1, 0)] == pytest.approx(
        cs[0, sphere.lm_index(1, 0)] + 4.0 * np.sqrt(4 * np.pi / 3), rel=1e-13
    )
    assert probr.hamiltonian(Q) == pytest.approx(sphere.energy(Wb[0]), rel=1e-13)
    _, Wm = iso.models.euler_sphere(N=N, W0=Wb[1])
    assert np.max(np.abs(Wm - Wb[1])) <= 1e-14  # validated: projected onto su(N)


def test_registry_builds_the_model() -> None:
    cfg = {"model": "euler-sphere", "params": {"N": 8, "omega": 0.5}, "dt": 0.1, "n_steps": 5}
    problem, y0, method, kwargs = iso.registry.build(cfg)
    assert problem.parameters["N"] == 8 and problem.parameters["omega"] == 0.5
    sol = iso.solve(problem, method, y0, **kwargs)
    assert sol.diagnostics is not None and sol.diagnostics.casimir_drift <= 1e-13


def test_errors_are_typed() -> None:
    for N in (1, 0, 2.5, True):
        with pytest.raises(iso.ParameterError):
            iso.models.euler_sphere(N=N)  # type: ignore[arg-type]
    for omega in (np.nan, np.inf, "fast", True, None):
        with pytest.raises(iso.ParameterError):
            iso.models.euler_sphere(N=8, omega=omega)  # type: ignore[arg-type]
    with pytest.raises(iso.ParameterError):
        iso.models.euler_sphere(N=8, initial="vortex")
    with pytest.raises(iso.ParameterError):
        iso.models.euler_sphere(N=8, lmax=8)
    with pytest.raises(iso.ParameterError):
        iso.models.euler_sphere(N=8, rms=0.0)
    with pytest.raises(iso.ParameterError):
        iso.models.euler_sphere(N=8, seed=1.5)  # type: ignore[arg-type]
    with pytest.raises(
        iso.ParameterError, match="euler_sphere: seed must be an integer >= 0, got -1"
    ):
        iso.models.euler_sphere(N=8, seed=-1)
    with pytest.raises(iso.ShapeError):
        iso.models.euler_sphere(N=8, initial=np.zeros(7))
    with pytest.raises(iso.ShapeError):
        iso.models.euler_sphere(N=4, initial=np.zeros(24))  # degree 4 > N - 1
    W = np.zeros((6, 6), complex)
    with pytest.raises(iso.ParameterError):
        iso.models.euler_sphere(N=6, initial=np.zeros(3), W0=W)
    with pytest.raises(iso.ShapeError):
        iso.models.euler_sphere(N=5, W0=W)
    with pytest.raises(iso.NotInSpaceError):
        iso.models.euler_sphere(N=6, W0=np.eye(6, dtype=complex))


def test_an_initial_function_must_be_real_and_finite() -> None:
    def wave(theta, phi):  # type: ignore[no-untyped-def]
        return np.exp(1j * phi) * np.sin(theta)  # complex: its real part alone was used

    with pytest.raises(iso.DtypeError, match=r"f returned complex values \(largest imaginary "
                       r"part 0\.\d+\); a vorticity is real"):  # fmt: skip
        iso.models.euler_sphere(N=8, initial=wave)
    with pytest.raises(iso.NonFiniteError, match="f returned non-finite values"):
        iso.models.euler_sphere(N=8, initial=lambda th, ph: np.where(th > 1, np.inf, 1.0))
    with pytest.raises(iso.DtypeError, match="f returned <U1 values, not real numbers"):
        iso.models.euler_sphere(N=8, initial=lambda th, ph: np.full(th.shape, "a"))
    _, real = iso.models.euler_sphere(N=8, initial=lambda th, ph: np.real(wave(th, ph)))
    _, zero_imag = iso.models.euler_sphere(N=8, initial=lambda th, ph: np.real(wave(th, ph)) + 0j)
    assert real.tobytes() == zero_imag.tobytes()


@pytest.mark.parametrize(
    ("model", "size", "state_bytes"),
    [
        ("euler_sphere", {"N": 20000}, 16 * 20000**2),
        ("rigid_body", {"n": 100000}, 8 * 100000**2),
        ("brockett", {"n": 20000}, 16 * 20000**2),
        ("toda", {"n": 100000}, 8 * 100000**2),
    ],
)
def test_a_model_too_large_for_the_memory_is_refused_before_it_allocates(
    model: str, size: dict[str, int], state_bytes: int, monkeypatch: pytest.MonkeyPatch
) -> None:
    import tracemalloc

    from isoflow.models import _checks

    monkeypatch.setattr(_checks, "available_memory", lambda: 8 * 2**30)
    factory = getattr(iso.models, model)
    peak = importlib.import_module(factory.__module__)._BUILD_PEAK_STATES
    ((key, value),) = size.items()
    need = f"{state_bytes * peak / 2**30:.1f} GiB"
    tracemalloc.start()
    try:
        with pytest.raises(iso.ParameterError) as err:
            factory(**size)
        assert tracemalloc.get_traced_memory()[1] < 2**20  # refused before building
    finally:
        tracemalloc.stop()
    assert str(err.value) == (
        f"{model}: {key} = {value} needs about {need} of memory to build ({peak:g} times the "
        f"{state_bytes / 2**30:.1f} GiB state), more than the 8.0 GiB available here; choose a "
        "smaller size"
    )
    small = {k: 16 for k in size}
    assert factory(**small)[1].shape[-1] == 16  # sizes that fit are built


def test_the_available_memory_is_known_here() -> None:
    from isoflow.models._checks import available_memory

    have = available_memory()
    assert have is not None and 2**20 < have < 2**50


def test_condensation_experiment_runs_and_plots() -> None:
    """A small version of the experiment: its summary, its checks on rounding, its figure."""
    res = iso.experiments.euler_sphere(N=16, T=10.0, progress=False)
    s = res.summary
    assert s["parameters"]["N"] == 16 and s["parameters"]["n_steps"] == 50  # h = 3.2 / N
    for key in ("casimirs_rounding", "casimir_traces_rounding", "angular_momentum_rounding"):
        assert s["checks"][key]["ok"], s["checks"][key]
    assert res.data["coefficients"].shape == (len(res.data["ts"]), 16 * 16 - 1)
    fig = iso.plotting.plot_experiment(res)
    assert len([ax for ax in fig.axes if ax.get_title()]) == 6
