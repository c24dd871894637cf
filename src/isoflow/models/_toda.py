r"""The non-periodic Toda lattice in Flaschka's variables, as an isospectral flow on ``sym(n)``.

``n`` particles on a line with exponential nearest-neighbour interaction,
:math:`H = \tfrac12\sum_i p_i^2 + \sum_{i<n} e^{q_i - q_{i+1}}`. Flaschka's change of variables

.. math::

    a_i = -\tfrac12 p_i \quad (i = 1..n), \qquad
    b_i = \tfrac12 e^{(q_i - q_{i+1})/2} \quad (i = 1..n-1)

turns Hamilton's equations into

.. math::

    \dot a_i = 2 (b_i^2 - b_{i-1}^2), \qquad \dot b_i = b_i (a_{i+1} - a_i)
    \qquad (b_0 = b_n = 0),

which is the Lax equation :math:`\dot L = [B(L), L]` for the symmetric tridiagonal (Jacobi)
matrix ``L`` with diagonal ``a`` and off-diagonals ``b``, and
:math:`B(L) = L_+ - L_-` (strictly upper minus strictly lower triangular part, skew-symmetric).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .._errors import ParameterError, ShapeError
from .._seeds import generator
from ..algebras import sym
from ..kernels import ElementwiseLinear
from ..problems import IsospectralProblem
from ._checks import check_n, real_parameter, require_memory

__all__ = ["jacobi_coefficients", "jacobi_matrix", "off_band", "toda"]

#: Peak memory of building the model, in states (tracemalloc, n = 1000 and 2000): a size
#: that does not fit in the available memory is refused before anything is allocated.
_BUILD_PEAK_STATES = 3.0

Array = NDArray[Any]


def jacobi_matrix(a: ArrayLike, b: ArrayLike) -> Array:
    """The symmetric tridiagonal matrix with diagonal ``a`` and off-diagonals ``b``.

    Parameters
    ----------
    a : array_like, shape ``(*batch, n)``
    b : array_like, shape ``(*batch, n - 1)``

    Returns
    -------
    L : ndarray, shape ``(*batch, n, n)``
    """
    a_ = np.asarray(a, dtype=np.float64)
    b_ = np.asarray(b, dtype=np.float64)
    if a_.ndim < 1 or b_.shape[-1:] != (a_.shape[-1] - 1,):
        raise ShapeError(
            f"jacobi_matrix: a must have shape (*batch, n) and b shape (*batch, n - 1), "
            f"got {a_.shape} and {b_.shape}"
        )
    batch = np.broadcast_shapes(a_.shape[:-1], b_.shape[:-1])
    n = a_.shape[-1]
    L = np.zeros((*batch, n, n))
    i = np.arange(n)
    L[..., i, i] = a_
    L[..., i[:-1], i[1:]] = b_
    L[..., i[1:], i[:-1]] = b_
    return L


def jacobi_coefficients(L: ArrayLike) -> tuple[Array, Array]:
    """Diagonal ``a`` and first super-diagonal ``b`` of ``L`` (shape ``(*batch, n, n)``)."""
    L_ = np.asarray(L)
    return (
        np.diagonal(L_, axis1=-2, axis2=-1).copy(),
        np.diagonal(L_, offset=1, axis1=-2, axis2=-1).copy(),
    )


def off_band(L: ArrayLike) -> Array:
    r"""Largest entry outside the tridiagonal band, :math:`\max_{|i-j|>1} |L_{ij}|`, per member.

    Zero along the exact Toda flow from a tridiagonal state; for IsoMP it measures how far the
    discrete state has left the Jacobi matrices (see :func:`toda`).

    Parameters
    ----------
    L : array_like, shape (*batch, n, n)
        Symmetric matrices (states of :func:`toda`).

    Returns
    -------
    ndarray, shape (*batch,)
    """
    L_ = np.asarray(L)
    n = L_.shape[-1]
    i = np.arange(n)
    mask = np.abs(i[:, None] - i[None, :]) > 1
    if not mask.any():
        return np.zeros(L_.shape[:-2])
    return np.max(np.abs(L_[..., mask]), axis=-1)


def toda(
    n: int = 12,
    *,
    a: ArrayLike | None = None,
    b: ArrayLike | None = None,
    seed: int | np.random.Generator | None = None,
) -> tuple[IsospectralProblem, Array]:
    r"""The non-periodic Toda lattice :math:`\dot L = [B(L), L]` on ``sym(n)`` (Flaschka form).

    Equations, with ``L`` the Jacobi matrix of diagonal ``a`` and off-diagonals ``b``
    (:func:`jacobi_matrix`):

    .. math::

        B(L) = L_+ - L_-, \qquad
        \dot a_i = 2 (b_i^2 - b_{i-1}^2), \qquad \dot b_i = b_i (a_{i+1} - a_i),

    with :math:`b_0 = b_n = 0`; :math:`L_\pm` are the strictly upper/lower triangular parts.
    ``B`` is linear and skew-symmetric, so it lies in the normalizer :math:`\mathfrak{so}(n)` of
    ``sym(n)``. ``B`` is defined on all of ``sym(n)`` (the *full* symmetric Toda flow, which
    maps Jacobi matrices to Jacobi matrices). Its exact derivative ``B_jvp(L, dL) = B(dL)`` is
    supplied, so Newton's Jacobian is exact.

    **Sign and sorting.** With this sign (Flaschka's; :math:`a_i = -p_i/2`,
    :math:`b_i = \tfrac12 e^{(q_i - q_{i+1})/2}`), as :math:`t \to +\infty` the off-diagonals
    :math:`b_i` tend to zero exponentially (:math:`b_i \sim e^{-(\lambda_i - \lambda_{i+1})t}`)
    and the diagonal tends to the eigenvalues in **descending** order,
    :math:`a_1 \to \lambda_{\max}, \dots, a_n \to \lambda_{\min}` (Moser 1975; Symes: the flow
    at integer times is the unshifted QR algorithm on :math:`e^{L}`). The opposite sign
    :math:`L_- - L_+ = [\operatorname{diag}(1..n), L]`, i.e. Brockett's flow with
    :math:`N = \operatorname{diag}(1, \dots, n)` on Jacobi matrices, runs time backwards and
    sorts ascending.

    **Invariants.** The eigenvalues of ``L`` (Casimirs, from the algebra). The Hamiltonian
    :math:`H = \tfrac12\operatorname{Tr}L^2 = \tfrac12\sum a_i^2 + \sum b_i^2`
    (:math:`= \tfrac14` of the Toda energy in :math:`(q, p)`) is itself a spectral invariant,
    :math:`\tfrac12\sum\lambda_i^2`, so IsoMP conserves it to rounding, not merely up to
    :math:`O(h^2)`. ``invariants["off_band"]`` is :func:`off_band`, zero along the exact flow.

    **What IsoMP preserves.** Exactly (to rounding): the spectrum, the symmetry of ``L`` (every
    state is projected onto ``sym(n)``), and therefore ``H``. Not exactly: the tridiagonal
    band. A step is :math:`L_{k+1} = C L_k C^{-1}` with the Cayley factor ``C`` of
    :math:`B(X)`, where the stage :math:`X = L_k + \tfrac h2[B(X), X] + \tfrac{h^2}4 B(X) X
    B(X)` is pentadiagonal (from the triple product), so each step creates off-band entries of
    size :math:`O(h^3)` (measured: one step from ``toda(seed=0)`` gives ``6.1e-4`` at
    ``h = 0.1``, ``7.8e-5`` at ``h = 0.05``). Over a run they accumulate to :math:`O(h^2)`:
    for the default state (``n = 12``, ``T = 200``) the largest off-band entry is ``2.1e-3``
    at ``h = 0.1``, ``5.4e-4`` at ``h = 0.05`` and ``1.35e-4`` at ``h = 0.025`` (``1.4e-2``
    at ``h = 0.1`` for ``seed=0``), reached early (``t ~ 1.4``) on the ``(i, i+2)`` entries;
    it then decays with the flow to below ``1e-30`` as ``L`` approaches its diagonal limit.
    RK4 and the classical midpoint rule preserve the band exactly but not the spectrum.

    Parameters
    ----------
    n : int
        Number of particles, ``n >= 2`` (default 12).
    a, b : array_like, optional
        Initial diagonal, shape ``(*batch, n)``, and off-diagonals, shape ``(*batch, n - 1)``;
        ``b`` must be non-zero (a Jacobi matrix with non-zero ``b`` has simple spectrum). Give
        both or neither.
    seed : int, numpy.random.Generator, optional
        Without ``a`` and ``b``: a seeded random state, ``a_i`` standard normal and ``b_i``
        uniform on ``[0.5, 1.5)``. Without ``seed`` either: the default state ``a_i = 0``,
        ``b_i = 1`` (the lattice released from rest with equal spacings
        :math:`q_{i+1} - q_i = -2\ln 2`), whose eigenvalues are known in closed form,
        :math:`\lambda_k = 2\cos(k\pi/(n+1))`, ``k = 1..n``.

    Returns
    -------
    problem : IsospectralProblem
        On ``sym(n)``, with ``hamiltonian`` and ``invariants = {"off_band": off_band}``.
    L0 : ndarray, shape ``(*batch, n, n)``
        The initial Jacobi matrix.

    Raises
    ------
    ParameterError
        ``n < 2``, a zero ``b_i``, only one of ``a``, ``b``, or ``seed`` together with them.
    ShapeError, DtypeError, NonFiniteError
        Malformed ``a`` or ``b``.

    References
    ----------
    H. Flaschka, The Toda lattice. II. Existence of integrals, Phys. Rev. B 9 (1974) 1924–1925.
    J. Moser, Finitely many mass points on the line under the influence of an exponential
    potential — an integrable system, Lecture Notes in Physics 38 (1975) 467–497.
    W. W. Symes, The QR algorithm and scattering for the finite nonperiodic Toda lattice,
    Physica D 4 (1982) 275–280.

    Examples
    --------
    >>> import numpy as np, isoflow as iso
    >>> prob, L0 = iso.models.toda(n=12)
    >>> sol = iso.solve(prob, iso.IsoMP(), L0, dt=0.1, t1=200.0, save_every=100)
    >>> a_T = np.diag(sol.y_final)
    >>> bool(np.all(np.diff(a_T) < 0))  # sorted in descending order
    True
    """
    n = check_n(n, 2, "toda")
    require_memory(8.0 * n * n, _BUILD_PEAK_STATES, f"toda: n = {n}")
    if (a is None) != (b is None):
        raise ParameterError("toda: give both a and b, or neither")
    if a is not None and b is not None:
        if seed is not None:
            raise ParameterError("toda: seed is only used without a and b; give one or the other")
        a_ = real_parameter(a, "a")
        b_ = real_parameter(b, "b")
        if a_.shape[-1:] != (n,) or b_.shape[-1:] != (n - 1,):
            raise ShapeError(
                f"toda: a must have shape (*batch, {n}) and b shape (*batch, {n - 1}), "
                f"got {a_.shape} and {b_.shape}"
            )
        if np.any(b_ == 0):
            raise ParameterError(
                "toda: the off-diagonals b_i must be non-zero (b_i = exp((q_i - q_{i+1})/2)/2)"
            )
    elif seed is not None:
        rng = generator(seed, "toda: seed")
        a_ = rng.standard_normal(n)
        b_ = rng.uniform(0.5, 1.5, n - 1)
    else:
        a_, b_ = np.zeros(n), np.ones(n - 1)
    L0 = jacobi_matrix(a_, b_)

    i = np.arange(n)
    sign = np.sign(i[None, :] - i[:, None]).astype(np.float64)  # +1 above, -1 below diagonal
    sign.setflags(write=False)

    def B(L: Array) -> Array:
        return sign * L

    def hamiltonian(L: Array) -> Array:
        return 0.5 * np.sum(L * L, axis=(-2, -1))

    problem = IsospectralProblem(
        B=B,
        algebra=sym(n),
        B_jvp=lambda L, dL: B(dL),
        kernel=ElementwiseLinear(sign),  # B = sign o L: the compiled fast path applies
        hamiltonian=hamiltonian,
        invariants={"off_band": off_band},
        name=f"non-periodic Toda lattice, n = {n} (Flaschka)",
        parameters={"n": n, "seed": seed},
    )
    return problem, L0
