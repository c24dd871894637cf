"""isoflow.sphere: the Hoppe-Yau Laplacian, quantized harmonics, grid transforms, diagnostics.

Every expected value comes from an independent computation: dense double commutators and
Kronecker-product operators, analytic spherical harmonics, the spin algebra, continuum
formulas. Tolerances are stated next to each assertion.
"""

from __future__ import annotations

import numpy as np
import pytest
from matplotlib.figure import Figure
from scipy.linalg import eigh_tridiagonal

import isoflow as iso
from isoflow import sphere
from isoflow.sphere import compiled

RNG = np.random.default_rng(20240601)


def random_su(N: int, seed: int = 0, batch: tuple[int, ...] = ()) -> np.ndarray:
    rng = np.random.default_rng(seed)
    A = rng.standard_normal((*batch, N, N)) + 1j * rng.standard_normal((*batch, N, N))
    W = A - np.conj(np.swapaxes(A, -1, -2))
    tr = np.trace(W, axis1=-2, axis2=-1)[..., None, None] / N
    return W - tr * np.eye(N)


def double_commutator(W: np.ndarray) -> np.ndarray:
    """The definition: sum_a [S_a, [S_a, W]] with dense spin matrices."""
    out = np.zeros_like(W)
    for S in sphere.spin_matrices(W.shape[-1]):
        C = S @ W - W @ S
        out += S @ C - C @ S
    return out


def dense_operator(N: int) -> np.ndarray:
    """The N^2 x N^2 matrix of Delta_N on row-major vec(W), from Kronecker products."""
    I = np.eye(N)
    L = np.zeros((N * N, N * N), dtype=complex)
    for S in sphere.spin_matrices(N):
        ad = np.kron(S, I) - np.kron(I, S.T)
        L += ad @ ad
    return L


def real_Y(l: int, m: int, theta: np.ndarray, phi: np.ndarray) -> np.ndarray:
    """A few real orthonormal harmonics written out in Cartesian coordinates."""
    x, y, z = np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)
    table = {
        (1, -1): np.sqrt(3 / (4 * np.pi)) * y,
        (1, 0): np.sqrt(3 / (4 * np.pi)) * z,
        (1, 1): np.sqrt(3 / (4 * np.pi)) * x,
        (2, -2): np.sqrt(15 / (4 * np.pi)) * x * y,
        (2, -1): np.sqrt(15 / (4 * np.pi)) * y * z,
        (2, 0): np.sqrt(5 / (16 * np.pi)) * (3 * z**2 - 1),
        (2, 1): np.sqrt(15 / (4 * np.pi)) * x * z,
        (2, 2): np.sqrt(15 / (16 * np.pi)) * (x**2 - y**2),
        (3, -3): np.sqrt(35 / (32 * np.pi)) * (3 * x**2 - y**2) * y,
        (3, 0): np.sqrt(7 / (16 * np.pi)) * (5 * z**3 - 3 * z),
        (3, 2): np.sqrt(105 / (16 * np.pi)) * (x**2 - y**2) * z,
    }
    return table[(l, m)]


# ---- the Laplacian -------------------------------------------------------------------------


@pytest.mark.parametrize("N", [2, 3, 4, 7, 12])
def test_tridiagonal_laplacian_equals_double_commutator(N: int) -> None:
    W = RNG.standard_normal((3, N, N)) + 1j * RNG.standard_normal((3, N, N))  # any matrices
    ref = double_commutator(W)
    got = sphere.laplacian(W)
    assert np.max(np.abs(got - ref)) <= 1e-13 * np.max(np.abs(ref))


@pytest.mark.parametrize("N", [5, 8])
def test_blocks_are_the_operator_on_each_diagonal(N: int) -> None:
    """laplacian_block(N, m) is Delta_N restricted to diagonal m (entries (i+m, i), or
    (i, i-m) for m < 0), read off the dense double commutator of unit matrices."""
    for m in range(-(N - 1), N):
        n = N - abs(m)
        rows = np.arange(n) + max(m, 0)
        cols = np.arange(n) + max(-m, 0)
        block = np.zeros((n, n))
        for j in range(n):
            E = np.zeros((N, N), dtype=complex)
            E[rows[j], cols[j]] = 1.0
            D = double_commutator(E)
            block[:, j] = D[rows, cols].real
            others = D.copy()
            others[rows, cols] = 0
            assert np.max(np.abs(others)) <= 1e-12  # nothing leaves the diagonal
        d, e = sphere.laplacian_block(N, m)
        assert np.max(np.abs(np.diag(d) + np.diag(e, 1) + np.diag(e, -1) - block)) <= 1e-12


@pytest.mark.parametrize("N", [2, 5, 9])
def test_spectrum_is_minus_l_l_plus_one_with_multiplicity(N: int) -> None:
    lam = np.linalg.eigvalsh(dense_operator(N))  # Hermitian: ad_S is skew-adjoint
    expected = np.sort(np.concatenate([np.full(2 * l + 1, -l * (l + 1.0)) for l in range(N)]))
    assert np.max(np.abs(np.sort(lam) - expected)) <= 1e-11 * N * N
    for m in range(N):  # and block by block, through the tridiagonal formula
        d, e = sphere.laplacian_block(N, m)
        mu = eigh_tridiagonal(d, e, eigvals_only=True) if d.size > 1 else d
        ls = np.arange(m, N)
        assert np.max(np.abs(np.sort(mu) - np.sort(-ls * (ls + 1.0)))) <= 1e-11 * N * N


@pytest.mark.parametrize("N", [2, 3, 8, 33, 64])
def test_poisson_solve_inverts_the_laplacian_on_su(N: int) -> None:
    W = random_su(N, seed=N, batch=(2,))
    P = sphere.solve_poisson(W)
    assert P.shape == W.shape
    assert np.max(np.abs(sphere.laplacian(P) - W)) <= 1e-12 * np.max(np.abs(W))
    assert np.max(np.abs(np.trace(P, axis1=-2, axis2=-1))) <= 1e-13 * np.max(np.abs(W))
    assert np.max(np.abs(P + np.conj(np.swapaxes(P, -1, -2)))) <= 1e-14 * np.max(np.abs(P))


def test_poisson_solve_matches_the_dense_pseudo_inverse_and_ignores_the_trace() -> None:
    N = 6
    W = random_su(N, seed=3)
    L = dense_operator(N)
    ref = (np.linalg.pinv(L) @ W.ravel()).reshape(N, N)  # minimum norm: traceless
    X = W + 0.7j * np.eye(N)  # a u(N) stage: its trace part is the kernel, removed
    assert np.max(np.abs(sphere.solve_poisson(X) - ref)) <= 1e-13
    out = np.empty_like(X)
    c = sphere.laplacian_coefficients(N)
    compiled.poisson_solve(X, out, c.inv_piv, c.mult)  # the kernel on one matrix
    assert np.max(np.abs(out - ref)) <= 1e-13


def test_poisson_solve_is_accurate_at_large_N_on_the_singular_diagonal() -> None:
    """The main diagonal (whose block is singular) is solved as accurately as the others:
    compare with the eigendecomposition of its block, at N = 512."""
    N = 512
    d, e = sphere.laplacian_block(N, 0)
    lam, V = eigh_tridiagonal(d, e)
    keep = lam < -1.0  # l >= 1 (lambda = -l(l+1) <= -2)
    w = np.random.default_rng(1).standard_normal(N)
    w -= w.mean()
    ref = V[:, keep] @ ((V[:, keep].T @ w) / lam[keep])
    P = sphere.solve_poisson(np.diag(1j * w))
    assert np.max(np.abs(P.diagonal().imag - ref)) <= 1e-11 * np.max(np.abs(ref))
    assert np.max(np.abs(P - np.diag(P.diagonal()))) == 0.0  # zonal stays zonal


def test_laplacian_coefficients_are_cached_read_only_and_O_N2() -> None:
    c = sphere.laplacian_coefficients(40)
    assert sphere.laplacian_coefficients(40) is c
    for arr in (c.diag, c.inv_piv, c.mult):
        assert arr.shape == (40, 40) and not arr.flags.writeable
    assert c.gamma.shape == (41,)


def test_hbar_and_coordinates() -> None:
    for N in (2, 5, 10):
        assert sphere.hbar(N) == pytest.approx(2 / np.sqrt(N * N - 1), rel=1e-15)
        X = [-1j * sphere.hbar(N) * S for S in sphere.spin_matrices(N)]
        assert np.allclose(sum(x @ x for x in X), np.eye(N), atol=1e-13)  # unit sphere
        # [X_1, X_2] = i hbar X_3: the quantized {x, y} = z
        assert np.allclose(X[0] @ X[1] - X[1] @ X[0], 1j * sphere.hbar(N) * X[2], atol=1e-13)


# ---- quantized harmonics ------------------------------------------------------------------


def test_basis_is_orthonormal_and_made_of_eigenvectors() -> None:
    N = 7
    mats = [
        sphere.basis_matrix(N, l, m) for l in range(1, N) for m in range(-l, l + 1)
    ]  # fmt: skip
    B = np.array([T.ravel() for T in mats])
    G = (4 * np.pi / N) * (B.conj() @ B.T)
    assert np.max(np.abs(G - np.eye(len(mats)))) <= 1e-13
    for T in mats:
        assert np.max(np.abs(T - T.conj().T)) <= 1e-15  # real harmonics: Hermitian
    for l in range(N):
        for m in range(-l, l + 1):
            T = sphere.basis_matrix(N, l, m, kind="complex")
            assert np.max(np.abs(double_commutator(T) + l * (l + 1) * T)) <= 1e-12
            sign = -1 if m % 2 else 1
            Tm = sphere.basis_matrix(N, l, -m, kind="complex")
            assert np.max(np.abs(Tm - sign * T.conj().T)) <= 1e-15


def test_phases_follow_the_ladder_of_the_spherical_harmonics() -> None:
    """[J_+-, T_lm] = sqrt((l -+ m)(l +- m + 1)) T_{l,m+-1} and T_l0 > 0 at the north pole."""
    N = 9
    S1, S2, _ = sphere.spin_matrices(N)
    Jp = -1j * (S1 + 1j * S2)
    Jm = -1j * (S1 - 1j * S2)
    for l in range(N):
        assert sphere.basis_matrix(N, l, 0, kind="complex")[N - 1, N - 1].real > 0
        for m in range(-l, l + 1):
            T = sphere.basis_matrix(N, l, m, kind="complex")
            if m < l:
                up = sphere.basis_matrix(N, l, m + 1, kind="complex")
                c = np.sqrt((l - m) * (l + m + 1.0))
                assert np.max(np.abs(Jp @ T - T @ Jp - c * up)) <= 1e-12
            if m > -l:
                down = sphere.basis_matrix(N, l, m - 1, kind="complex")
                c = np.sqrt((l + m) * (l - m + 1.0))
                assert np.max(np.abs(Jm @ T - T @ Jm - c * down)) <= 1e-12


def test_degree_one_harmonics_are_the_quantized_coordinates() -> None:
    """Y_11, Y_1-1, Y_10 (real) = sqrt(3/4pi) (x, y, z)  <->  sqrt(3/4pi) hbar (J1, J2, J3)."""
    N = 11
    X = [-1j * sphere.hbar(N) * S for S in sphere.spin_matrices(N)]
    k = np.sqrt(3 / (4 * np.pi))
    for m, Xa in ((1, X[0]), (-1, X[1]), (0, X[2])):
        assert np.max(np.abs(sphere.basis_matrix(N, 1, m) - k * Xa)) <= 1e-14
    # complex Y_11 = -sqrt(3/8 pi)(x + iy)
    T11 = sphere.basis_matrix(N, 1, 1, kind="complex")
    assert np.max(np.abs(T11 + np.sqrt(3 / (8 * np.pi)) * (X[0] + 1j * X[1]))) <= 1e-14


def test_products_converge_to_products_of_functions() -> None:
    """T(z) T(z) -> T(z^2): z^2 = 1/3 + (4/3) sqrt(pi/5) Y_20, error O(1/N^2)."""
    errs = []
    for N in (8, 16, 32, 64):
        X3 = -1j * sphere.hbar(N) * sphere.spin_matrices(N)[2]
        c = sphere.to_coefficients(1j * X3 @ X3)
        exact = np.zeros_like(c)
        exact[sphere.lm_index(2, 0)] = 4 / 3 * np.sqrt(np.pi / 5)
        errs.append(np.max(np.abs(c - exact)))
    rates = np.log2(np.array(errs[:-1]) / np.array(errs[1:]))
    assert np.all(rates > 1.9) and errs[-1] < 1e-3


def test_the_bases_are_computed_once_per_size_within_the_budget(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """The transforms keep the bases of the last ``N`` (within ``BASES_CACHE_BYTES``): the
    tridiagonal eigensolves run once, the kept arrays cannot be written, and the coefficients
    are those computed afresh bit for bit (the spectra of every saved chunk of a forced run
    cost products, not ``N`` eigensolves)."""
    from isoflow.sphere import _basis

    calls = []
    raw = _basis._raw_eigenvectors
    monkeypatch.setattr(_basis, "_raw_eigenvectors", lambda N, m: (calls.append(m), raw(N, m))[1])
    monkeypatch.setattr(_basis, "_bases_kept", [])
    W = np.stack([iso.models.euler_sphere(N=24, seed=s)[1] for s in range(3)])
    first = sphere.to_coefficients(W)
    assert len(calls) == 24
    back = sphere.from_coefficients(first, 24)
    assert len(calls) == 24  # no eigensolve after the first transform
    assert all(not V.flags.writeable for V in _basis._bases_kept[0][1])
    monkeypatch.setattr(_basis, "BASES_CACHE_BYTES", 0)  # nothing kept: computed afresh
    assert sphere.to_coefficients(W).tobytes() == first.tobytes()
    assert sphere.from_coefficients(first, 24).tobytes() == back.tobytes()
    assert len(calls) == 24 + 2 * 24


@pytest.mark.parametrize("N", [2, 5, 16, 41])
def test_coefficient_round_trips(N: int) -> None:
    c = np.random.default_rng(N).standard_normal((2, N * N - 1))
    W = sphere.from_coefficients(c, N)
    assert W.shape == (2, N, N)
    assert np.max(np.abs(W + np.conj(np.swapaxes(W, -1, -2)))) == 0.0
    assert np.max(np.abs(np.trace(W, axis1=-2, axis2=-1))) <= 1e-13 * N
    assert np.max(np.abs(sphere.to_coefficients(W) - c)) <= 1e-13 * N
    V = random_su(N, seed=N + 1, batch=(2,))
    assert np.max(np.abs(sphere.from_coefficients(sphere.to_coefficients(V), N) - V)) <= (
        1e-13 * N * np.max(np.abs(V))
    )


def test_to_coefficients_projects_onto_su_and_from_coefficients_pads() -> None:
    N = 6
    V = random_su(N, seed=2)
    H = np.random.default_rng(3).standard_normal((N, N))
    H = H + H.T  # a Hermitian part and a trace: projected away
    assert np.allclose(sphere.to_coefficients(V + H + 2j * np.eye(N)), sphere.to_coefficients(V))
    c = np.random.default_rng(4).standard_normal(sphere.coefficient_count(3))
    full = np.zeros(N * N - 1)
    full[: c.size] = c
    gap = np.max(np.abs(sphere.from_coefficients(c, N) - sphere.from_coefficients(full, N)))
    assert gap <= 1e-15  # the same sums, up to the order of additions
    assert np.allclose(sphere.to_coefficients(sphere.from_coefficients(c, N), lmax=3), c)


def test_coefficient_layout() -> None:
    ls, ms = sphere.degree_order(3)
    assert sphere.coefficient_count(3) == 15 == ls.size
    assert list(zip(ls[:4], ms[:4], strict=True)) == [(1, -1), (1, 0), (1, 1), (2, -2)]
    for k, (l, m) in enumerate(zip(ls, ms, strict=True)):
        assert sphere.lm_index(l, m) == k


def test_basis_is_stable_at_large_N() -> None:
    """Entries near the poles are tiny for large m; the ladder phases still hold there:
    T_{l,m+1} against [J_+, T_lm] computed diagonal-wise, N = 160."""
    N = 160
    a = np.arange(N, dtype=float)
    c = np.sqrt((a + 1.0) * (N - a - 1.0))
    prev = None
    for m, V in sphere.diagonal_bases(N):
        assert np.max(np.abs(V.T @ V - np.eye(N - m))) <= 1e-12
        if prev is not None:
            b = np.arange(N - m)
            U = c[b + m - 1, None] * prev[b, 1:] - c[b, None] * prev[b + 1, 1:]
            ls = np.arange(m, N)
            expected = np.sqrt((ls - m + 1.0) * (ls + m))
            assert np.max(np.abs(U - V * expected) / expected) <= 1e-9
        prev = V
        if m > 40:
            break


# ---- grids ----------------------------------------------------------------------------------


@pytest.mark.parametrize("geometry", ["CC", "GL", "F1"])
def test_synthesis_matches_analytic_harmonics(geometry: str) -> None:
    theta, phi = sphere.grid(12, 25, geometry)
    T, P = np.meshgrid(theta, phi, indexing="ij")
    for l, m in [(1, -1), (1, 0), (1, 1), (2, -2), (2, -1), (2, 0), (2, 1), (2, 2), (3, -3),
                 (3, 0), (3, 2)]:  # fmt: skip
        c = np.zeros(sphere.coefficient_count(4))
        c[sphere.lm_index(l, m)] = 1.0
        vals = sphere.synthesize(c, 12, 25, geometry=geometry)
        assert np.max(np.abs(vals - real_Y(l, m, T, P))) <= 1e-14
        pts = sphere.evaluate(c, T[::3, ::4], P[::3, ::4])
        assert np.max(np.abs(pts - real_Y(l, m, T[::3, ::4], P[::3, ::4]))) <= 1e-9


@pytest.mark.parametrize("geometry", ["CC", "GL", "F1"])
def test_analysis_inverts_synthesis_for_band_limited_data(geometry: str) -> None:
    lmax = 12
    c = np.random.default_rng(5).standard_normal((3, sphere.coefficient_count(lmax)))
    ntheta = lmax + 2
    vals = sphere.synthesize(c, ntheta, 2 * lmax + 1, geometry=geometry)
    assert vals.shape == (3, ntheta, 2 * lmax + 1)
    assert np.max(np.abs(sphere.analyze(vals, lmax, geometry=geometry) - c)) <= 1e-13


def test_functions_and_matrices_on_the_grid() -> None:
    # f = x z + 3: exactly sqrt(4 pi/15) Y_21; the mean 3 is dropped
    c = sphere.from_function(lambda t, p: np.sin(t) * np.cos(p) * np.cos(t) + 3.0, 5)
    expected = np.zeros_like(c)
    expected[sphere.lm_index(2, 1)] = np.sqrt(4 * np.pi / 15)
    assert np.max(np.abs(c - expected)) <= 1e-14
    # the matrix of omega = z is i X_3; back on the grid it is cos(theta)
    N = 9
    W = sphere.vorticity_from_function(lambda t, p: np.cos(t), N)
    X3 = -1j * sphere.hbar(N) * sphere.spin_matrices(N)[2]
    assert np.max(np.abs(W - 1j * X3)) <= 1e-14
    theta, _ = sphere.grid(10, 20)
    vals = sphere.to_grid(W, 10, 20)
    assert np.max(np.abs(vals - np.cos(theta)[:, None])) <= 1e-14


# ---- diagnostics ----------------------------------------------------------------------------


def test_energy_enstrophy_and_spectra_against_coefficient_formulas() -> None:
    N = 12
    c = np.random.default_rng(6).standard_normal((2, N * N - 1))
    W = sphere.from_coefficients(c, N)
    ls, _ = sphere.degree_order(N - 1)
    H = 0.5 * np.sum(c**2 / (ls * (ls + 1.0)), axis=-1)
    assert np.allclose(sphere.energy(W), H, rtol=1e-13)
    P = (np.linalg.pinv(dense_operator(N)) @ W[0].ravel()).reshape(N, N)
    assert sphere.energy(W[0]) == pytest.approx(
        -2 * np.pi / N * np.trace(P.conj().T @ W[0]).real, rel=1e-12
    )
    Z = sphere.enstrophy(W)
    assert np.allclose(Z, 0.5 * np.sum(c**2, axis=-1), rtol=1e-13)
    E = sphere.energy_spectrum(W)
    assert E.shape == (2, N - 1)
    assert np.allclose(E.sum(-1), 2 * H, rtol=1e-13)
    assert np.allclose(sphere.energy_spectrum(c), E, rtol=1e-12)
    Zl = sphere.enstrophy_spectrum(c)
    assert np.allclose(Zl[:, 2], np.sum(c[:, 8:15] ** 2, axis=-1))  # l = 3: indices 8..14


def test_casimirs_are_traces_of_powers() -> None:
    N = 10
    W = random_su(N, seed=7, batch=(2,))
    C = sphere.casimirs(W, kmax=6)
    assert C.shape == (2, 5)
    for j, k in enumerate(range(2, 7)):
        Om = -1j * W
        ref = (4 * np.pi / N) * np.trace(np.linalg.matrix_power(Om, k), axis1=-2, axis2=-1).real
        assert np.allclose(C[:, j], ref, rtol=1e-12, atol=1e-12 * np.max(np.abs(ref)))
    assert np.allclose(C[:, 0], 2 * sphere.enstrophy(W), rtol=1e-12)
    lev = sphere.vorticity_levels(W)
    assert lev.shape == (2, N) and np.all(np.diff(lev, axis=-1) >= 0)


def test_angular_momentum_is_the_integral_of_omega_times_x() -> None:
    """L = int omega x dA = sqrt(4 pi/3) (omega_11, omega_1-1, omega_10)."""
    N = 8
    c = np.random.default_rng(8).standard_normal(N * N - 1)
    L = sphere.angular_momentum(sphere.from_coefficients(c, N))
    k = np.sqrt(4 * np.pi / 3)
    expected = k * c[[sphere.lm_index(1, 1), sphere.lm_index(1, -1), sphere.lm_index(1, 0)]]
    assert np.allclose(L, expected, rtol=1e-13)


# ---- initial data ---------------------------------------------------------------------------


def test_random_initial_data_band_rms_seed_and_spectrum() -> None:
    c = sphere.random_coefficients(12, lmin=3, rms=2.0, seed=4)
    ls, _ = sphere.degree_order(12)
    assert np.all(c[ls < 3] == 0) and np.any(c[ls == 3] != 0)
    assert np.sum(c**2) / (4 * np.pi) == pytest.approx(4.0, rel=1e-13)  # rms^2
    assert np.array_equal(c, sphere.random_coefficients(12, lmin=3, rms=2.0, seed=4))
    assert not np.array_equal(c, sphere.random_coefficients(12, lmin=3, rms=2.0, seed=5))
    # slope: the mean spectrum over many seeds follows l^slope (relative spread of the mean
    # of 400 chi-square(2l+1) samples is below 7% for l >= 2)
    E = np.mean(
        [sphere.energy_spectrum(sphere.random_coefficients(20, slope=-3.0, seed=s))
         for s in range(400)], axis=0,
    )  # fmt: skip
    l = np.arange(1, 21)
    ratio = E / l**-3.0
    assert np.max(np.abs(ratio[1:] / np.mean(ratio[1:]) - 1)) < 0.2
    W = sphere.random_vorticity(16, seed=1)
    assert W.shape == (16, 16)
    assert np.max(np.abs(sphere.to_coefficients(W)[sphere.coefficient_count(10) :])) <= 1e-13


# ---- figures --------------------------------------------------------------------------------


def test_figures_are_labelled_figures(tmp_path) -> None:  # type: ignore[no-untyped-def]
    N = 8
    W = sphere.random_vorticity(N, seed=2)
    figs = [
        sphere.plot_map(W),
        sphere.plot_orthographic(W, centers=[(30, 0), (-30, 120), (90, 0)], resolution=60),
        sphere.plot_energy_spectrum({"t = 0": W, "given": sphere.energy_spectrum(W)}),
        sphere.plot_invariants(
            np.arange(3.0),
            casimirs=sphere.casimirs(np.stack([W, W, W])),
            energy=np.ones(3),
            enstrophy=np.ones(3),
        ),
    ]
    for fig in figs:
        assert isinstance(fig, Figure)
        fig.savefig(tmp_path / "f.png")
        labelled = [ax for ax in fig.axes if ax.get_xlabel() or ax.get_title()]
        assert labelled
    ax = figs[0].axes[0]
    assert "longitude" in ax.get_xlabel() and "latitude" in ax.get_ylabel()
    assert "N = 8" in ax.get_title()
    states = np.stack([W, 2 * W, 3 * W])
    gif = sphere.animate(states, tmp_path / "movie.gif", ts=[0.0, 1.0, 2.0], fps=2)
    assert gif.exists() and gif.read_bytes()[:3] == b"GIF"
    gif2 = sphere.animate(states, tmp_path / "o.gif", kind="orthographic")
    assert gif2.stat().st_size > 1000


def test_mp4_without_ffmpeg_is_a_clear_error(tmp_path) -> None:  # type: ignore[no-untyped-def]
    from matplotlib import animation

    if animation.writers.is_available("ffmpeg"):
        pytest.skip("ffmpeg is installed here")
    W = sphere.random_vorticity(6, seed=0)
    with pytest.raises(iso.ParameterError, match="ffmpeg"):
        sphere.animate(np.stack([W, W]), tmp_path / "m.mp4")


# ---- errors ---------------------------------------------------------------------------------


def test_errors_are_typed() -> None:
    for bad in (1, 0, 2.5, True, "8"):
        with pytest.raises(iso.ParameterError):
            sphere.laplacian_coefficients(bad)  # type: ignore[arg-type]
        with pytest.raises(iso.ParameterError):
            sphere.from_coefficients(np.zeros(3), bad)  # type: ignore[arg-type]
    with pytest.raises(iso.ShapeError):
        sphere.laplacian(np.zeros((3, 4)))
    with pytest.raises(iso.ShapeError):
        sphere.solve_poisson(np.zeros(5))
    with pytest.raises(iso.ShapeError, match="coefficients"):
        sphere.from_coefficients(np.zeros(5), 4)  # 5 is no (lmax+1)^2 - 1
    with pytest.raises(iso.ShapeError, match="degree"):
        sphere.from_coefficients(np.zeros(24), 4)  # lmax = 4 > N - 1 = 3
    with pytest.raises(iso.DtypeError):
        sphere.from_coefficients(np.zeros(3, dtype=complex), 4)
    with pytest.raises(iso.NonFiniteError):
        sphere.from_coefficients(np.array([1.0, np.nan, 0.0]), 4)
    with pytest.raises(iso.ParameterError):
        sphere.to_coefficients(np.zeros((4, 4), complex), lmax=4)
    with pytest.raises(iso.ShapeError):
        sphere.analyze(np.zeros((5, 9)), 6, geometry="GL")  # grid too coarse for degree 6
    with pytest.raises(TypeError, match="geometry"):  # no default: another grid's values
        sphere.analyze(np.zeros((16, 33)), 6)  # would give wrong coefficients silently
    with pytest.raises(iso.ParameterError):
        sphere.synthesize(np.zeros(3), geometry="HEALPix")
    with pytest.raises(iso.ParameterError):
        sphere.random_coefficients(5, lmin=6)
    with pytest.raises(iso.ParameterError):
        sphere.random_coefficients(5, rms=-1.0)
    with pytest.raises(iso.ParameterError):
        sphere.random_vorticity(4, lmax=4)
    with pytest.raises(iso.ParameterError):
        sphere.lm_index(2, 3)
    with pytest.raises(iso.ParameterError):
        sphere.laplacian_block(4, 4)
    with pytest.raises(iso.ShapeError):
        sphere.from_function(lambda t, p: np.zeros(3), 4)
    with pytest.raises(iso.ParameterError):
        sphere.animate(np.zeros((2, 3)), "movie.avi")


_W8 = sphere.random_vorticity(8, seed=2)


def _axes():  # type: ignore[no-untyped-def]
    return Figure().subplots()


_STATES = np.stack([_W8, _W8])
_E8 = sphere.energy_spectrum(_W8)


@pytest.mark.parametrize(
    ("call", "error", "message"),
    [
        (lambda p: sphere.plot_orthographic(_W8, centers=["north"]), iso.ParameterError,
         r"plot_orthographic: a centre is \(latitude, longitude\) in degrees, got 'north'"),
        (lambda p: sphere.plot_orthographic(_W8, centers=[(30,)]), iso.ParameterError,
         r"a centre is \(latitude, longitude\) in degrees, got \(30,\)"),
        (lambda p: sphere.plot_orthographic(_W8, centers=[(np.nan, 0)]), iso.ParameterError,
         r"a finite latitude in \[-90, 90\] and a finite longitude"),
        (lambda p: sphere.plot_orthographic(_W8, centers=[(120, 0)]), iso.ParameterError,
         r"a finite latitude in \[-90, 90\]"),
        (lambda p: sphere.plot_orthographic(_W8, centers=(30, 0)), iso.ParameterError,
         r"a centre is \(latitude, longitude\) in degrees, got 30"),
        (lambda p: sphere.plot_orthographic(_W8, resolution=0), iso.ParameterError,
         r"plot_orthographic: resolution must be >= 3, got 0"),
        (lambda p: sphere.plot_orthographic(_W8, resolution=-3), iso.ParameterError,
         r"resolution must be >= 3, got -3"),
        (lambda p: sphere.plot_orthographic(_W8, resolution=2.5), iso.ParameterError,
         r"resolution must be an integer, got 2.5"),
        (lambda p: sphere.plot_map(_W8, ntheta=0), iso.ParameterError,
         r"draw_map: ntheta must be >= 2, got 0"),
        (lambda p: sphere.plot_map(_W8, vmax=0.0), iso.ParameterError,
         r"draw_map: vmax must be a positive finite number, got 0.0"),
        (lambda p: sphere.figures.draw_field_lines(_axes(), _W8, ntheta=0), iso.ParameterError,
         r"draw_field_lines: ntheta must be >= 2, got 0"),  # was the default grid, silently
        (lambda p: sphere.figures.draw_field_lines(_axes(), _W8, nphi=2.5), iso.ParameterError,
         r"draw_field_lines: nphi must be an integer, got 2.5"),
        (lambda p: sphere.plot_map(_W8, vmax=np.nan), iso.ParameterError,
         r"vmax must be a positive finite number, got nan"),
        (lambda p: sphere.animate(_STATES, p / "a.gif", fps=0), iso.ParameterError,
         r"animate: fps must be >= 1, got 0"),
        (lambda p: sphere.animate(_STATES, p / "a.gif", dpi=0), iso.ParameterError,
         r"animate: dpi must be a positive finite number, got 0"),
        (lambda p: sphere.animate(_STATES, p / "a.gif", ts=[0.0, 1.0, 2.0]), iso.ShapeError,
         r"animate: ts must have shape \(2,\), one per time, got \(3,\)"),
        (lambda p: sphere.animate(_STATES, p / "a.gif", ts=[0.0, np.inf]), iso.NonFiniteError,
         r"animate: ts must be finite"),
        (lambda p: sphere.animate(_STATES, p / "a.gif", kind="orthographic", center=5),
         iso.ParameterError, r"animate: a centre is \(latitude, longitude\) in degrees, got 5"),
        (lambda p: sphere.plot_invariants([], energy=[]), iso.ShapeError,
         r"plot_invariants: ts must have shape \(n_t,\) with n_t >= 1, got \(0,\)"),
        (lambda p: sphere.plot_invariants([0, 1, 2], energy=[1.0, 2.0]), iso.ShapeError,
         r"plot_invariants: energy must have shape \(3,\), one per time, got \(2,\)"),
        (lambda p: sphere.plot_invariants([0, 1, 2], casimirs=np.ones((2, 3))), iso.ShapeError,
         r"plot_invariants: casimirs must have shape \(3, K\), one row per time, got \(2, 3\)"),
        (lambda p: sphere.plot_invariants(np.ones((2, 2)), energy=[1.0, 2.0]), iso.ShapeError,
         r"plot_invariants: ts must have shape \(n_t,\)"),
        (lambda p: sphere.plot_energy_spectrum({"a": np.stack([_E8, _E8])}), iso.ShapeError,
         r"spectrum 'a': give E_l for l = 1..lmax as a non-empty real vector, got shape \(2, 7\)"),
        (lambda p: sphere.plot_energy_spectrum({}), iso.ShapeError,
         r"draw_energy_spectrum: give at least one spectrum"),
    ],
)  # fmt: skip
def test_figure_arguments_are_checked_with_one_line_errors(call, error, message, tmp_path) -> None:  # type: ignore[no-untyped-def]
    with pytest.raises(error, match=message) as err:
        call(tmp_path)
    assert "\n" not in str(err.value)
    assert list(tmp_path.iterdir()) == []  # no movie started


def test_the_spectrum_axis_spans_the_values_drawn() -> None:
    ax = Figure().subplots()
    E = np.array([1.0, 0.1, 1e-3, 1e-17, 0.0])  # 1e-17: rounding of a degree the data lack
    sphere.figures.draw_energy_spectrum(ax, {"E": E})
    drawn = ax.get_lines()[0].get_ydata()
    assert np.array_equal(np.isnan(drawn), [False, False, False, True, True])
    assert ax.get_ylim() == pytest.approx((1e-3 / 3, 3.0))
