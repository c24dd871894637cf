r"""Dissipation on the sphere: a linear part diagonal in the quantized spherical harmonics.

:math:`L = -c(-\Delta_N)` with the rate per degree :math:`c_l`, e.g.
:math:`c_l = \nu\, l(l+1) + \nu_p\, (l(l+1))^p + \alpha` for viscosity, hyperviscosity and linear
drag. Every :math:`T_{lm}` decays at its rate: :math:`e^{\tau L} T_{lm} = e^{-c_l\tau} T_{lm}`.

Per diagonal, exactly
---------------------
:math:`\Delta_N` is tridiagonal on each diagonal ``m`` of the matrix (:func:`laplacian_block`),
so :math:`f(\Delta_N)` acts on diagonal ``m`` as :math:`V_m\,f(\Lambda_m)\,V_m^T` with
:math:`V_m` its eigenvectors. The block is persymmetric (:math:`\Delta_N` commutes with the
reflection :math:`z \mapsto -z`): its eigenvectors are even or odd under ``i -> n - 1 - i``,
so in the sums :math:`a_i = x_i + x_{n-1-i}` and differences :math:`b_i = x_i - x_{n-1-i}` the
matrix splits into two symmetric blocks of half the size, each the same function of a folded
tridiagonal matrix (computed with ``eigh_tridiagonal``, its eigenvalues rounded to the exact
:math:`-l(l+1)`). A half step then reads :math:`\sum_m (N-m)^2/4 \approx N^3/12` numbers (the
blocks' upper triangles) and does as many complex-by-real multiply–adds, on the lower diagonals
only; the upper ones are their mirrors. The matrices depend on :math:`\tau`: they are computed
once per step size (``O(N^4/16)`` flops, a few seconds at ``N = 1024``; the memory,
``8 N^3/12`` bytes, is checked first).
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Sequence
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .._errors import ParameterError, ShapeError
from ..splitting import LinearPart, StochasticForcing, decay_factors, phi_factors
from ._basis import bases, degree_order, from_coefficients, lm_index
from ._operators import check_N, laplacian_block

__all__ = ["SphereDissipation", "band_forcing", "band_modes", "degree_rates", "folded_blocks"]

Array = NDArray[Any]


def degree_rates(
    N: int,
    viscosity: float = 0.0,
    hyperviscosity: tuple[float, float] | None = None,
    drag: float = 0.0,
) -> Array:
    r"""The rates :math:`c_l = \nu\lambda_l + \nu_p\lambda_l^p + \alpha`,
    :math:`\lambda_l = l(l+1)`, ``l = 0..N-1``.

    Parameters
    ----------
    N : int
        Matrix size (degrees ``0..N-1``).
    viscosity : float
        :math:`\nu \ge 0` (default 0), finite.
    hyperviscosity : (float, float), optional
        ``(nu_p, p)``: the coefficient :math:`\nu_p \ge 0` and the order :math:`p \ge 1` of
        the term :math:`\nu_p\lambda_l^p` (default: none).
    drag : float
        :math:`\alpha \ge 0` (default 0), finite: a linear drag on every degree.

    Returns
    -------
    ndarray, shape (N,)
        :math:`c_l` for ``l = 0..N-1``.

    Raises
    ------
    ParameterError
        A negative or non-finite coefficient, ``p < 1``, a malformed ``hyperviscosity``.
    """
    N = check_N(N)

    def coefficient(v: Any, what: str) -> float:
        if isinstance(v, bool) or not isinstance(v, (int, float, np.integer, np.floating)):
            raise ParameterError(f"{what} must be a real number, got {v!r}")
        if not np.isfinite(v):
            raise ParameterError(f"{what} must be finite, got {v!r}")
        if v < 0:
            raise ParameterError(
                f"{what} must be >= 0 (a negative {what} makes the modes grow), got {v!r}"
            )
        return float(v)

    nu = coefficient(viscosity, "viscosity")
    alpha = coefficient(drag, "drag")
    lam = np.arange(N, dtype=float) * np.arange(1, N + 1, dtype=float)
    c = nu * lam + alpha
    if hyperviscosity is not None:
        try:
            nu_p, p = hyperviscosity
        except (TypeError, ValueError):
            raise ParameterError(
                f"hyperviscosity must be a pair (nu_p, p), got {hyperviscosity!r}"
            ) from None
        nu_p = coefficient(nu_p, "hyperviscosity nu_p")
        p = coefficient(p, "hyperviscosity order p")
        if p < 1:
            raise ParameterError(f"hyperviscosity order p must be >= 1, got {p!r}")
        c = c + nu_p * lam**p
    return c


def _folds(N: int) -> Iterator[tuple[Array, Array, Array, Array]]:
    """Per diagonal ``m``: the eigenvectors and degrees of its even and odd folded blocks
    (one diagonal at a time: ``O(N^2)`` memory)."""
    return (folded_blocks(N, m) for m in range(N))


def folded_blocks(N: int, m: int) -> tuple[Array, Array, Array, Array]:
    r"""``(Ve, le, Vo, lo)``: orthonormal eigenvectors and degrees ``l`` of the even and odd
    parts of diagonal ``m``'s block of :math:`\Delta_N`, in the orthonormal coordinates
    :math:`(x_i \pm x_{n-1-i})/\sqrt2` (and :math:`x_{\mathrm{mid}}` for the even part of an
    odd length ``n = N - m``)."""
    from scipy.linalg import eigh_tridiagonal

    d, e = laplacian_block(N, m)
    n = d.size
    h2, odd = n // 2, n % 2
    de, ee = d[: h2 + odd].copy(), e[: h2 + odd - 1].copy() if h2 + odd > 1 else np.zeros(0)
    do, eo = d[:h2].copy(), e[: max(h2 - 1, 0)].copy()
    if odd:
        if h2:
            ee[h2 - 1] = np.sqrt(2.0) * e[h2 - 1]
    elif h2:
        de[h2 - 1] += e[h2 - 1]
        do[h2 - 1] -= e[h2 - 1]

    def eig(dd: Array, ee_: Array) -> tuple[Array, Array]:
        if dd.size == 0:
            return np.zeros((0, 0)), np.zeros(0, dtype=np.int64)
        if dd.size == 1:
            lam, V = dd.copy(), np.ones((1, 1))
        else:
            lam, V = eigh_tridiagonal(dd, ee_)
        l = np.rint((-1.0 + np.sqrt(np.maximum(1.0 - 4.0 * lam, 0.0))) / 2.0).astype(np.int64)
        return V, l

    Ve, le = eig(de, ee)
    Vo, lo = eig(do, eo)
    return Ve, le, Vo, lo


def _folded_matrices(
    fold: tuple[Array, Array, Array, Array], f: Array, n: int
) -> tuple[Array, Array]:
    """``(Me, Mo)``: :math:`V f(l) V^T` of the even and odd part, in the sums
    :math:`x_i + x_{n-1-i}` and differences (see the module docstring)."""
    Ve, le, Vo, lo = fold
    h2, odd = n // 2, n % 2
    D = np.full(h2 + odd, np.sqrt(0.5))
    if odd:
        D[h2] = 1.0
    Me = (Ve * f[le]) @ Ve.T
    Me = D[:, None] * Me * D[None, :]
    Mo = 0.5 * ((Vo * f[lo]) @ Vo.T)
    return Me, Mo


class SphereDissipation(LinearPart):
    r"""The linear part :math:`L T_{lm} = -c_l T_{lm}` on ``su(N)`` or ``u(N)``.

    Parameters
    ----------
    N : int
    rates : array_like, shape (N,)
        :math:`c_l \ge 0` for ``l = 0..N-1`` (:func:`degree_rates`).

    Notes
    -----
    Its modes (for stochastic forcing) are the real harmonics :math:`iT^{\mathrm r}_{lm}`,
    numbered as the coefficients (:func:`~isoflow.sphere.lm_index`, ``l >= 1``).
    """

    name = "sphere dissipation"

    def __init__(self, N: int, rates: ArrayLike) -> None:
        self.N = check_N(N, "SphereDissipation: N")
        c = np.asarray(rates, dtype=float)
        if c.shape != (self.N,):
            raise ShapeError(
                f"SphereDissipation: need N = {self.N} rates (l = 0..N-1), got {c.shape}"
            )
        if not np.all(np.isfinite(c)) or np.any(c < 0):
            raise ParameterError("SphereDissipation: rates must be finite and >= 0")
        self.degree_rates = c
        self._packed: dict[float, tuple[Array, Array, Array]] = {}

    # ---- LinearPart ---------------------------------------------------------------------------
    def check(self, algebra: Any) -> None:
        from ..algebras import SpecialUnitary, Unitary

        if not isinstance(algebra, (SpecialUnitary, Unitary)) or algebra.shape != (self.N,) * 2:
            raise ParameterError(
                f"SphereDissipation(N = {self.N}) acts on su({self.N}) or u({self.N}), not on "
                f"{algebra.name}"
            )

    @property
    def uniform_rate(self) -> float | None:
        """The one rate of every degree, if they are all equal (a linear drag alone, or none),
        else ``None``. Such a flow is the scaling :math:`e^{-c\\tau} W`: no per-diagonal
        matrices are built (``8 N^3 / 12`` bytes), and a half step is one pass over ``W``."""
        c = self.degree_rates
        return float(c[0]) if np.all(c == c[0]) else None

    @property
    def rates(self) -> Array:
        """Per mode (the coefficient layout of :func:`~isoflow.sphere.lm_index`, ``l >= 1``)."""
        ls = np.repeat(np.arange(1, self.N), 2 * np.arange(1, self.N) + 1)
        return self.degree_rates[ls]

    def flow(self, W: Array, tau: float) -> Array:
        c = self.uniform_rate
        if c is not None:
            d = float(np.exp(-c * tau))
            Wa = np.asarray(W, dtype=np.complex128)
            return Wa * d if d != 1.0 else Wa.copy()
        return self._apply(W, decay_factors(self.degree_rates, tau), self._matrices(tau))

    def integral(self, F: Array, tau: float) -> Array:
        f = phi_factors(self.degree_rates, tau)
        return self._apply(F, f, None)

    def modes(self, index: ArrayLike) -> Array:
        idx = np.asarray(index, dtype=np.int64).reshape(-1)
        coef = np.zeros((idx.size, self.N * self.N - 1))
        coef[np.arange(idx.size), idx] = 1.0
        return from_coefficients(coef, self.N)

    def mode_patterns(self, index: ArrayLike) -> Any:
        """The real harmonics ``index`` as sparse rows of ``N^2`` entries, built diagonal by
        diagonal: harmonic ``(l, m)`` lives on the diagonals ``m`` and ``-m`` (``2 (N - |m|)``
        entries), so a forcing band costs ``O(N)`` memory a mode instead of a dense ``N x N``
        matrix (:meth:`modes` gives the same values)."""
        from scipy import sparse

        N = self.N
        idx = np.asarray(index, dtype=np.int64).reshape(-1)
        ls_all, ms_all = degree_order(N - 1)
        ls, ms = ls_all[idx], ms_all[idx]
        scale = float(np.sqrt(N / (4.0 * np.pi)))  # the basis' norm, as from_coefficients
        indptr = np.zeros(idx.size + 1, dtype=np.int64)
        per_row: list[tuple[Array, Array]] = [(np.zeros(0, np.int64), np.zeros(0, complex))] * (
            idx.size
        )
        wanted = np.unique(np.abs(ms))
        for m, V in bases(N, int(wanted.max()) if wanted.size else 0):
            rows = np.flatnonzero(np.abs(ms) == m)
            if rows.size == 0:
                continue
            i = np.arange(N - m)
            for r in rows:
                col = V[:, ls[r] - m] * scale
                if m == 0:
                    per_row[r] = (i * N + i, 1j * col)
                    continue
                sign = -1.0 if m % 2 else 1.0
                z = 1j if ms[r] > 0 else 1.0  # the imaginary (m > 0) or real (m < 0) part
                low = (sign / np.sqrt(2.0)) * (z * col + 0j)
                flat = np.concatenate([(i + m) * N + i, i * N + i + m])
                vals = np.concatenate([low, -np.conj(low)])
                order = np.argsort(flat, kind="stable")
                per_row[r] = (flat[order], vals[order])
        indptr[1:] = np.cumsum([len(f) for f, _ in per_row])
        out = sparse.csr_array(
            (
                np.concatenate([v for _, v in per_row]) if idx.size else np.zeros(0, complex),
                np.concatenate([f for f, _ in per_row]) if idx.size else np.zeros(0, np.int64),
                indptr,
            ),
            shape=(idx.size, N * N),
        )
        out.eliminate_zeros()
        return out

    def compiled(self, taus: Sequence[float], algebra: Any) -> Any:
        """The record the compiled split stage applies for the half steps ``taus``.

        Parameters
        ----------
        taus : sequence of float
            The lengths of the half steps of one step.
        algebra : Algebra
            The problem's space (unused here: the part holds its ``N``).

        Returns
        -------
        object
            A uniform decay when every degree has the same rate, else the per-diagonal
            folded flows of :mod:`isoflow.sphere.compiled`.
        """
        from .compiled import SphereFlow

        c = self.uniform_rate
        if c is not None:
            from .._compiled.stages.split import UniformFlow

            return UniformFlow(np.exp(-c * np.asarray(taus, dtype=float)))
        packs = [self._packed_for(t) for t in taus]
        offe, offo = packs[0][1], packs[0][2]
        data = np.ascontiguousarray(np.stack([p[0] for p in packs]))
        return SphereFlow(self.N, data, offe, offo)

    def describe(self) -> dict[str, Any]:
        return {"name": self.name, "N": self.N, "rates": self.degree_rates.tolist()}

    # ---- the per-diagonal application ---------------------------------------------------------
    def _matrices(self, tau: float) -> Callable[[int], tuple[Array, Array]]:
        """The folded matrices of diagonal ``m`` for the decay over ``tau``, unpacked from the
        cache the compiled stage reads too."""
        packed, offe, offo = self._packed_for(tau)

        def matrices(m: int) -> tuple[Array, Array]:
            n = self.N - m
            return (
                _unpack(packed, int(offe[m]), n // 2 + n % 2),
                _unpack(packed, int(offo[m]), n // 2),
            )

        return matrices

    def _packed_for(self, tau: float) -> tuple[Array, Array, Array]:
        """The upper triangles of every diagonal's folded decay matrices over ``tau``
        (cached per ``tau``), with the offsets of each diagonal's even and odd block."""
        hit = self._packed.get(tau)
        if hit is not None:
            return hit
        from ..models._checks import require_memory

        N = self.N
        total = sum(_tri(n // 2 + n % 2) + _tri(n // 2) for n in range(1, N + 1))
        require_memory(8.0 * total, 1.0, f"the dissipation matrices of N = {N}")
        packed = np.empty(total)
        offe = np.empty(N, dtype=np.int64)
        offo = np.empty(N, dtype=np.int64)
        f = decay_factors(self.degree_rates, tau)
        o = 0
        for m, fold in enumerate(_folds(N)):
            n = N - m
            Me, Mo = _folded_matrices(fold, f, n)
            for M, off in ((Me, offe), (Mo, offo)):
                k = M.shape[0]
                off[m] = o
                packed[o : o + _tri(k)] = M[np.triu_indices(k)]
                o += _tri(k)
        self._packed[tau] = (packed, offe, offo)
        return self._packed[tau]

    def _apply(
        self, W: Array, f: Array, matrices: Callable[[int], tuple[Array, Array]] | None
    ) -> Array:
        """:math:`f(-\\Delta_N)\\,W` diagonal by diagonal (``f`` per degree)."""
        N = self.N
        Wa = np.asarray(W)
        out = np.array(Wa, dtype=np.complex128, copy=True)
        folds = _folds(N) if matrices is None else iter(())
        for m in range(N):
            n = N - m
            h2, odd = n // 2, n % 2
            if matrices is not None:
                Me, Mo = matrices(m)
            else:
                Me, Mo = _folded_matrices(next(folds), f, n)
            i = np.arange(n)
            x = Wa[..., i + m, i]
            p = np.arange(h2)
            a = x[..., p] + x[..., n - 1 - p]
            if odd:
                a = np.concatenate([a, x[..., h2 : h2 + 1]], axis=-1)
            b = x[..., p] - x[..., n - 1 - p]
            ya = a @ Me
            yb = b @ Mo
            y = np.empty_like(x)
            y[..., p] = ya[..., :h2] + yb
            y[..., n - 1 - p] = ya[..., :h2] - yb
            if odd:
                y[..., h2] = ya[..., h2]
            out[..., i + m, i] = y
            if m:
                out[..., i, i + m] = -np.conj(y)
        return out


def _tri(k: int) -> int:
    return k * (k + 1) // 2


def _unpack(packed: Array, off: int, k: int) -> Array:
    M = np.zeros((k, k))
    iu = np.triu_indices(k)
    M[iu] = packed[off : off + _tri(k)]
    return M + np.triu(M, 1).T


def band_modes(N: int, lf: int, dl: int = 0) -> Array:
    """The coefficient indices (:func:`~isoflow.sphere.lm_index`) of every order of the
    degrees ``lf - dl .. lf + dl``.

    Raises
    ------
    ParameterError
        A band that is not inside ``1 .. N - 1``.
    """
    N = check_N(N)
    for v, what in ((lf, "lf"), (dl, "dl")):
        if isinstance(v, bool) or not isinstance(v, (int, np.integer)):
            raise ParameterError(f"band forcing: {what} must be an integer, got {v!r}")
    if dl < 0 or lf - dl < 1 or lf + dl > N - 1:
        raise ParameterError(
            f"band forcing: the band l = {lf} +- {dl} must lie in 1..N-1 = 1..{N - 1}"
        )
    ls = np.arange(lf - dl, lf + dl + 1)
    return np.concatenate([lm_index(l, np.arange(-l, l + 1)) for l in ls]).astype(np.int64)


def band_forcing(
    N: int, lf: int, dl: int = 0, *, energy_rate: float = 1.0, seed: int = 0
) -> StochasticForcing:
    r"""White-in-time forcing of every mode with ``lf - dl <= l <= lf + dl``, injecting the
    mean energy rate ``energy_rate`` (:math:`\varepsilon`).

    All modes of the band get the same amplitude :math:`\sigma`. In the coefficients of the
    vorticity, :math:`d\omega_{lm} = \dots + \sigma\,d\beta_{lm}`, and with the energy
    :math:`E = \frac12\sum\omega_{lm}^2/(l(l+1))` Itô's formula gives the mean injection
    :math:`\varepsilon = \frac12\sigma^2\sum_{\text{band}} 1/(l(l+1))`, hence
    :math:`\sigma = \sqrt{2\varepsilon / \sum_{\text{band}} 1/(l(l+1))}`.

    Raises
    ------
    ParameterError
        A band outside ``1 .. N - 1``, a negative or non-finite ``energy_rate``, a bad seed.
    """
    modes = band_modes(N, lf, dl)
    eps = energy_rate
    if isinstance(eps, bool) or not isinstance(eps, (int, float, np.integer, np.floating)):
        raise ParameterError(f"band forcing: energy_rate must be a real number, got {eps!r}")
    if not np.isfinite(eps) or eps < 0:
        raise ParameterError(f"band forcing: energy_rate must be finite and >= 0, got {eps!r}")
    ls = np.repeat(np.arange(lf - dl, lf + dl + 1), 2 * np.arange(lf - dl, lf + dl + 1) + 1)
    sigma = np.sqrt(2.0 * float(eps) / np.sum(1.0 / (ls * (ls + 1.0))))
    return StochasticForcing(modes, sigma, seed)
