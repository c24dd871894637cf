r"""Brockett's double bracket flow on Hermitian matrices, Section 3.2 of the paper.

.. math::

    \dot W = [[N, W], W] = [B(W), W], \qquad B(W) = [N, W] = NW - WN,

for Hermitian ``N`` and ``W``; ``B(W)`` is skew-Hermitian, so it lies in the normalizer
:math:`\mathfrak{u}(n)` of :math:`\mathrm{Herm}(n)` and the flow is isospectral. It is the
gradient flow of :math:`\operatorname{Re}\operatorname{Tr}(WN)` on the isospectral manifold
(normal metric): :math:`\tfrac{d}{dt}\operatorname{Tr}(WN) = \|[N, W]\|_F^2 \ge 0`.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .._errors import DtypeError, NonFiniteError, ParameterError, ShapeError
from .._seeds import generator
from ..algebras import herm
from ..kernels import ElementwiseLinear
from ..problems import IsospectralProblem
from ._checks import check_n, require_memory

__all__ = ["BROCKETT_DEFAULT_SCALE", "brockett"]

Array = NDArray[Any]

#: Default spectral norm :math:`\|W_0\|_2` of the random initial state (see :func:`brockett`).
BROCKETT_DEFAULT_SCALE = 0.75

#: Peak memory of building the model, in states (tracemalloc, n = 1000 and 2000): a size
#: that does not fit in the available memory is refused before anything is allocated.
_BUILD_PEAK_STATES = 23.0


def _hermitian_N(N: ArrayLike | None, n: int) -> tuple[Array, Array | None]:
    """``N`` as a complex Hermitian matrix, and its real diagonal when ``N`` is diagonal."""
    if N is None:
        diag = np.arange(1.0, n + 1.0)
        return np.diag(diag).astype(np.complex128), diag
    arr = np.asarray(N)
    if arr.dtype.kind not in "iufc":
        raise DtypeError(f"brockett: N must be numeric, got dtype {arr.dtype}")
    arr = arr.astype(np.complex128)
    if not np.all(np.isfinite(arr)):
        raise NonFiniteError("All entries of N must be finite (found NaN or Inf).")
    if arr.shape == (n,):
        if np.any(arr.imag != 0):
            raise ParameterError("brockett: the diagonal of N must be real (N is Hermitian)")
        return np.diag(arr), arr.real.copy()
    if arr.shape != (n, n):
        raise ShapeError(
            f"brockett: N must be a Hermitian ({n}, {n}) matrix or its diagonal of shape "
            f"({n},), got shape {arr.shape}"
        )
    if not np.allclose(arr, arr.conj().T, rtol=1e-12, atol=1e-14 * np.max(np.abs(arr))):
        raise ParameterError("brockett: N must be Hermitian")
    arr = 0.5 * (arr + arr.conj().T)
    off = arr - np.diag(np.diag(arr))
    return arr, (np.diag(arr).real.copy() if not np.any(off) else None)


def brockett(
    n: int = 10,
    *,
    seed: int | np.random.Generator | None = 0,
    scale: float = BROCKETT_DEFAULT_SCALE,
    N: ArrayLike | None = None,
    W0: ArrayLike | None = None,
) -> tuple[IsospectralProblem, Array]:
    r"""Brockett's double bracket flow :math:`\dot W = [[N, W], W]` on ``herm(n)``.

    In the convention :math:`\dot W = [B(W), W]` of :class:`~isoflow.IsospectralProblem`,
    ``B(W) = [N, W] = NW - WN`` (skew-Hermitian for Hermitian ``N``, ``W``). The state is
    complex Hermitian and all arithmetic is complex (``complex128``).

    ``B`` is linear, so its exact derivative ``B_jvp(W, dW) = [N, dW]`` is supplied and Newton's
    Jacobian is exact.

    Properties of the exact flow (Brockett 1991), all checked by the tests:

    * isospectral: the eigenvalues of ``W`` are Casimirs (IsoMP keeps them to rounding);
    * :math:`L(W) = \operatorname{Re}\operatorname{Tr}(WN)` is non-decreasing,
      :math:`\dot L = \|[N, W]\|_F^2`; it is the problem's ``lyapunov`` function;
    * for ``N = diag(nu)`` with distinct entries and ``W_0`` with distinct eigenvalues,
      ``W(t)`` tends exponentially to a diagonal matrix whose entries are the eigenvalues of
      ``W_0`` sorted in the same order as ``nu``: **ascending** for the default
      ``N = diag(1, ..., n)``. The off-diagonal entry ``W_ij`` decays like
      :math:`\exp(-(\nu_i-\nu_j)(\lambda_i-\lambda_j)\, t)` near the limit.

    The flow is a gradient flow, not a Hamiltonian one: the problem has no ``hamiltonian``.

    Parameters
    ----------
    n : int
        Matrix size, ``n >= 2`` (default 10, as in the paper).
    seed : int, numpy.random.Generator or None
        Seed of the random initial state (default 0); ignored when ``W0`` is given.
    scale : float
        Spectral norm :math:`\|W_0\|_2` of the random initial state (default
        :data:`BROCKETT_DEFAULT_SCALE` ``= 0.75``). ``W_0 = scale * G / ||G||_2`` with ``G`` a
        Gaussian (GUE) Hermitian matrix, ``herm(n).random(seed)``. The paper draws the entries
        uniformly from (0, 1), which gives :math:`\|W_0\| \approx n/2 = 5` for ``n = 10``; with
        the default ``N`` the implicit step then does not converge at ``h = 0.1``.
        The default was measured for ``n = 10``, ``h = 0.1``, ``T = 1000`` over seeds 0-11:
        with ``scale = 0.75`` (:math:`h\|B(W_0)\|_2 \le 0.1 \cdot 2 \|N - \bar\nu I\|_2
        \|W_0\|_2 = 0.675`) fixed-point iteration needs at most about 50 iterations in a step
        (the limit is 200) and ``W(1000)`` is diagonal to ``1e-14``; at ``scale = 1`` some steps
        need 125 iterations and at ``scale = 1.5`` the iteration fails. Smaller scales shrink the
        eigenvalue gaps, which set the sorting rate (``scale = 0.5`` leaves ``3e-11``
        off-diagonal at ``T = 1000`` for seed 9). GUE eigenvalues repel each other, so the gaps
        are rarely tiny. For larger ``n`` or ``h`` choose a smaller ``scale`` (or Newton).
    N : array_like, optional
        Hermitian ``(n, n)`` matrix, or its real diagonal of shape ``(n,)``. Default
        ``diag(1, 2, ..., n)``.
    W0 : array_like, optional
        Initial state(s), Hermitian, shape ``(*batch, n, n)``; overrides ``seed`` and ``scale``.

    Returns
    -------
    problem : IsospectralProblem
        On ``herm(n)``, with ``lyapunov = Re Tr(W N)`` and the eigenvalues as Casimirs.
        ``problem.parameters`` records ``n``, ``N``, ``seed`` and ``scale``.
    W0 : ndarray, complex, shape ``(*batch, n, n)``
        The initial state.

    Raises
    ------
    ParameterError
        ``n < 2``, ``scale`` not positive and finite, ``N`` not Hermitian.
    ShapeError, DtypeError, NonFiniteError, NotInSpaceError
        Malformed ``N`` or ``W0``.

    References
    ----------
    R. W. Brockett, Dynamical systems that sort lists, diagonalize matrices, and solve linear
    programming problems, Linear Algebra Appl. 146 (1991) 79–91.
    M. Viviani, *A minimal-variable symplectic method for isospectral flows*, Section 3.2.

    Examples
    --------
    >>> import isoflow as iso
    >>> prob, W0 = iso.models.brockett(n=4, seed=1)
    >>> sol = iso.solve(prob, iso.IsoMP(), W0, dt=0.1, t1=10.0)
    >>> float(sol.diagnostics.lyapunov_max_decrease[()]) <= 1e-13
    True
    """
    n = check_n(n, 2, "brockett")
    require_memory(16.0 * n * n, _BUILD_PEAK_STATES, f"brockett: n = {n}")
    if isinstance(scale, bool) or not isinstance(scale, (int, float, np.integer, np.floating)):
        raise ParameterError(f"brockett: scale must be a real number, got {scale!r}")
    if not (np.isfinite(scale) and scale > 0):
        raise ParameterError(f"brockett: scale must be positive and finite, got {scale!r}")
    Nmat, nu = _hermitian_N(N, n)
    Nmat.setflags(write=False)
    alg = herm(n)

    if W0 is None:
        G = alg.random(generator(seed, "brockett: seed"))
        W_init = float(scale) * G / np.linalg.norm(G, 2)
        W_init = alg.project(W_init)
    else:
        W_init = alg.validate(W0, "W0")

    if nu is not None:
        gaps = (nu[:, None] - nu[None, :]).astype(np.float64)
        gaps.setflags(write=False)

        def B(W: Array) -> Array:
            return gaps * W

        def lyapunov(W: Array) -> Array:
            return np.real(np.diagonal(W, axis1=-2, axis2=-1)) @ nu

        kernel = ElementwiseLinear(gaps)
    else:
        NT = np.ascontiguousarray(Nmat.T)
        # the compiled path works in the eigenframe N = U diag(nu_U) U^H, where [N, .] is
        # entrywise (see ElementwiseLinear)
        nu_U, U = np.linalg.eigh(Nmat)
        kernel = ElementwiseLinear(nu_U[:, None] - nu_U[None, :], frame=U)

        def B(W: Array) -> Array:
            return Nmat @ W - W @ Nmat

        def lyapunov(W: Array) -> Array:
            return np.real(np.sum(W * NT, axis=(-2, -1)))

    problem = IsospectralProblem(
        B=B,
        algebra=alg,
        kernel=kernel,  # compiled fast path
        B_jvp=lambda W, dW: B(dW),
        lyapunov=lyapunov,
        name=f"Brockett double bracket flow on herm({n})",
        parameters={
            "n": n,
            "N": Nmat,
            "seed": seed if W0 is None else None,
            "scale": float(scale) if W0 is None else None,
        },
    )
    return problem, W_init
