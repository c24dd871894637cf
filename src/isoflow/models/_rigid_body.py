r"""The generalized (Manakov) rigid body on :math:`\mathfrak{so}(n)`, Section 3.1 of the paper.

The state is the body angular momentum :math:`W \in \mathfrak{so}(n)` and the dynamics is the
Lie–Poisson flow (Frobenius pairing) of a quadratic kinetic energy:

.. math::

    H(W) = \tfrac12 \operatorname{Tr}\big((\mathcal I^{-1} W)^T W\big)
         = \tfrac12 \sum_{i,j} c_{ij} W_{ij}^2, \qquad
    \dot W = -[\mathcal I^{-1} W, W] = [W, \Omega], \qquad
    B(W) = -\mathcal I^{-1} W = -\Omega,

where the inverse inertia acts entrywise, :math:`\Omega_{ij} = (\mathcal I^{-1}W)_{ij} =
c_{ij} W_{ij}`, with a symmetric array of positive coefficients :math:`c_{ij} = 1/I_{ij}`
(:math:`I_{ij}` is the moment of inertia of the body for rotations in the plane
:math:`(e_i, e_j)`). Because ``c`` is symmetric, :math:`\mathcal I^{-1}` maps
:math:`\mathfrak{so}(n)` to itself and ``B`` takes values in the normalizer
:math:`\mathfrak{so}(n)`.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .._errors import ParameterError, ShapeError
from ..algebras import so
from ..kernels import ElementwiseLinear
from ..problems import IsospectralProblem
from ._checks import check_n, real_parameter, require_memory
from ._noise import transport_noise

__all__ = ["ParameterError", "paper_inertia_d", "rigid_body", "so_basis"]

#: Peak memory of building the model, in states (tracemalloc, n = 1000 and 2000): a size
#: that does not fit in the available memory is refused before anything is allocated.
_BUILD_PEAK_STATES = 4.2

Array = NDArray[Any]


def paper_inertia_d(n: int) -> Array:
    r"""The paper's inertia weights generalized to any ``n``: :math:`d_i = 1/\min(i, n+1-i)`.

    For ``n = 10`` this is ``(1, 1/2, 1/3, 1/4, 1/5, 1/5, 1/4, 1/3, 1/2, 1)`` (paper, Section
    3.1, with the symmetrization of the corrections to the paper: :math:`c_{ij} = (d_i + d_j)/2`).
    """
    n = check_n(n, 1, "paper_inertia_d")
    i = np.arange(1, n + 1)
    return 1.0 / np.minimum(i, n + 1 - i)


def so_basis(n: int) -> Array:
    r"""The orthonormal basis :math:`(E_{ij} - E_{ji})/\sqrt 2`, ``i < j``, of
    :math:`\mathfrak{so}(n)` (Frobenius), shape ``(n(n-1)/2, n, n)``."""
    i, j = np.triu_indices(n, 1)
    E = np.zeros((i.size, n, n))
    r = np.arange(i.size)
    E[r, i, j] = 1.0 / np.sqrt(2.0)
    E[r, j, i] = -1.0 / np.sqrt(2.0)
    return E


def _plane_moments_from_principal(moments: Array) -> Array:
    """Plane moments of a 3-d body: the plane ``(j, k)`` gets ``I_i`` for ``{i, j, k} = {1,2,3}``.

    With the hat map ``W_32 = a_1, W_13 = a_2, W_21 = a_3`` a rotation about axis ``e_i`` is a
    rotation in the plane of the other two axes, so ``Omega_jk = W_jk / I_i``.
    """
    plane = np.zeros((3, 3))
    plane[1, 2] = plane[2, 1] = moments[0]
    plane[0, 2] = plane[2, 0] = moments[1]
    plane[0, 1] = plane[1, 0] = moments[2]
    return plane


def rigid_body(
    n: int = 10,
    *,
    inertia: ArrayLike | None = None,
    d: ArrayLike | None = None,
    W0: ArrayLike | None = None,
    noise: float | ArrayLike | None = None,
    noise_seed: int | None = None,
) -> tuple[IsospectralProblem, Array]:
    r"""The generalized rigid body on :math:`\mathfrak{so}(n)` and its initial state.

    Equations (paper, eqs. (15)–(16), inertia operator corrected):

    .. math::

        \dot W = -[\mathcal I^{-1}W, W], \qquad
        (\mathcal I^{-1}W)_{ij} = c_{ij} W_{ij}, \qquad
        H(W) = \tfrac12\operatorname{Tr}\big((\mathcal I^{-1}W)^T W\big)
             = \tfrac12 \sum_{i,j} c_{ij} W_{ij}^2,

    i.e. ``B(W) = -I^{-1} W`` in the convention :math:`\dot W = [B(W), W]` of
    :class:`~isoflow.IsospectralProblem`. With the Frobenius pairing
    :math:`\langle A, X\rangle = \operatorname{Tr}(A^T X)` one has :math:`\nabla H =
    \mathcal I^{-1} W` and :math:`B = (\nabla H)^T`, so the flow is Lie–Poisson and IsoMP
    preserves the coadjoint orbits (the eigenvalues of ``W``) to rounding and ``H`` up to a
    bounded :math:`O(h^2)` oscillation.

    The inverse inertia coefficients ``c`` are chosen by exactly one of:

    * default (``inertia`` and ``d`` both ``None``): the paper's weights
      :math:`c_{ij} = (d_i + d_j)/2` with :math:`d_i = 1/\min(i, n+1-i)`
      (:func:`paper_inertia_d`); for ``n = 10``,
      ``d = (1, 1/2, 1/3, 1/4, 1/5, 1/5, 1/4, 1/3, 1/2, 1)``. The paper prints the row scaling
      :math:`W_{ij}/d_i^{-1}`, which does not map :math:`\mathfrak{so}(n)` to itself; the
      symmetrized operator used here is the one whose energy is the printed ``H``.
    * ``d``: the same symmetrized operator for any positive weights ``d`` of shape ``(n,)``.
    * ``inertia`` of shape ``(n, n)``: the *plane moments* :math:`I_{ij} = I_{ji} > 0`
      (:math:`i \ne j`; the diagonal is ignored), :math:`\Omega_{ij} = W_{ij}/I_{ij}`, i.e.
      :math:`c_{ij} = 1/I_{ij}`. Manakov's body with mass-distribution eigenvalues
      :math:`J_i` is :math:`I_{ij} = J_i + J_j`; ``d`` corresponds to
      :math:`I_{ij} = 2/(d_i + d_j)`.
    * ``inertia`` of shape ``(3,)``, only for ``n = 3``: the *principal moments*
      :math:`(I_1, I_2, I_3)` of the classical body :math:`\dot m = m \times \omega`,
      :math:`\omega_k = m_k / I_k`. With the hat map :math:`\hat a b = a \times b`
      (:math:`W_{32} = a_1, W_{13} = a_2, W_{21} = a_3`), ``W = hat(m)`` follows exactly
      Euler's equations, and the plane moments are :math:`I_{23} = I_1`, :math:`I_{13} = I_2`,
      :math:`I_{12} = I_3` (:math:`\Omega_{32} = m_1/I_1`, etc.). Note that the Frobenius
      ``H`` is twice the classical kinetic energy :math:`\tfrac12\sum_k m_k^2/I_k`, because
      :math:`\operatorname{Tr}(\hat a^T \hat b) = 2 a\cdot b`; the time scale is the same.

    Parameters
    ----------
    n : int
        Matrix size, ``n >= 2`` (default 10, as in the paper).
    inertia : array_like, optional
        Plane moments, shape ``(n, n)``, or principal moments, shape ``(3,)`` when ``n = 3``.
        Off-diagonal entries must be positive and ``inertia`` symmetric.
    d : array_like, optional
        Positive weights of the symmetrized paper operator, shape ``(n,)``.
    W0 : array_like, optional
        Initial state(s), shape ``(*batch, n, n)``, skew-symmetric. Default: the paper's
        :math:`(W_0)_{ij} = 1/10` for :math:`i < j`, :math:`W_0^T = -W_0`.
    noise : float or array_like, optional
        Stratonovich transport noise :math:`\sum_i [\Xi_i, W] \circ d\beta_i` (the stochastic
        rigid body, :class:`~isoflow.noise.TransportNoise`; integrate with
        :class:`~isoflow.StochasticIsoMP`): a number :math:`\sigma` gives one field per
        orthonormal basis element of :math:`\mathfrak{so}(n)`,
        :math:`\Xi_{(ij)} = \sigma (E_{ij} - E_{ji})/\sqrt2` (for ``n = 3``: random torques
        about the three body axes); an array ``(m, n, n)`` of skew matrices gives the fields.
    noise_seed : int, optional
        Seed of the noise's increments (required with ``noise``; see :mod:`isoflow.noise`).

    Returns
    -------
    problem : IsospectralProblem
        On ``so(n)`` with ``hamiltonian``, the exact linear ``B_jvp``, and the eigenvalues as
        Casimirs (from the algebra). ``problem.parameters`` records ``n``, the plane moments
        ``inertia`` (``inf`` on the diagonal) and the coefficient array ``inverse_inertia``.
    W0 : ndarray, shape ``(*batch, n, n)``
        The initial state.

    Raises
    ------
    ParameterError
        ``n < 2``, non-positive or non-symmetric ``inertia``, non-positive ``d``, or both
        ``inertia`` and ``d`` given.
    ShapeError
        ``inertia``, ``d`` or ``W0`` of the wrong shape.
    DtypeError, NonFiniteError
        Complex/non-numeric or NaN/Inf parameters.
    NotInSpaceError
        ``W0`` is not skew-symmetric.

    References
    ----------
    M. Viviani, *A minimal-variable symplectic method for isospectral flows*, Section 3.1
    (the corrected inertia operator: *Corrections to the paper*, ``docs/theory/method.rst``).
    S. V. Manakov, Note on the integration of Euler's equations of the dynamics of an
    n-dimensional rigid body, Funct. Anal. Appl. 10 (1976) 328–329.
    T. Ratiu, The motion of the free n-dimensional rigid body, Indiana Univ. Math. J. 29 (1980).

    Examples
    --------
    >>> import isoflow as iso
    >>> prob, W0 = iso.models.rigid_body(n=10)
    >>> sol = iso.solve(prob, iso.IsoMP(), W0, dt=0.1, t1=1.0)
    >>> bool(sol.diagnostics.casimir_drift < 1e-13)
    True
    """
    n = check_n(n, 2, "rigid_body")
    require_memory(8.0 * n * n, _BUILD_PEAK_STATES, f"rigid_body: n = {n}")
    if inertia is not None and d is not None:
        raise ParameterError("rigid_body: give either inertia or d, not both")

    d_used: Array | None = None
    if inertia is None:
        if d is None:
            d_used = paper_inertia_d(n)
        else:
            d_used = real_parameter(d, "d")
            if d_used.shape != (n,):
                raise ShapeError(f"rigid_body: d must have shape ({n},), got {d_used.shape}")
            if np.any(d_used <= 0):
                raise ParameterError(f"rigid_body: d must be positive, got {d_used}")
        c = 0.5 * (d_used[:, None] + d_used[None, :])
        with np.errstate(divide="ignore"):
            plane = 1.0 / c
    else:
        arr = real_parameter(inertia, "inertia")
        if arr.ndim == 1 and n == 3:
            if arr.shape != (3,):
                raise ShapeError(
                    f"rigid_body: principal moments must have shape (3,), got {arr.shape}"
                )
            if np.any(arr <= 0):
                raise ParameterError(
                    f"rigid_body: principal moments of inertia must be positive, got {arr}"
                )
            plane = _plane_moments_from_principal(arr)
        elif arr.shape == (n, n):
            plane = arr.copy()
        else:
            extra = " or principal moments of shape (3,)" if n == 3 else ""
            raise ShapeError(
                f"rigid_body: inertia must be plane moments of shape ({n}, {n}){extra}, "
                f"got shape {arr.shape}"
            )
        off = ~np.eye(n, dtype=bool)
        if np.any(plane[off] <= 0):
            raise ParameterError(
                "rigid_body: plane moments of inertia I_ij (i != j) must be positive, "
                f"smallest is {float(np.min(plane[off]))}"
            )
        if not np.allclose(plane[off], plane.T[off], rtol=1e-12, atol=0.0):
            raise ParameterError("rigid_body: the plane moments of inertia must be symmetric")
        plane = 0.5 * (plane + plane.T)
        c = np.where(off, 1.0 / np.where(off, plane, 1.0), 0.0)
    np.fill_diagonal(plane, np.inf)
    c.setflags(write=False)

    alg = so(n)
    if W0 is None:
        W_init = np.triu(np.full((n, n), 0.1), 1)
        W_init = W_init - W_init.T
    else:
        W_init = alg.validate(W0, "W0")

    def B(W: Array) -> Array:
        return -c * W

    def B_jvp(W: Array, dW: Array) -> Array:
        return -c * dW

    def hamiltonian(W: Array) -> Array:
        return 0.5 * np.sum(c * W * W, axis=(-2, -1))

    parameters: dict[str, Any] = {"n": n, "inertia": plane, "inverse_inertia": c}
    if d_used is not None:
        parameters["d"] = d_used
    transport = transport_noise("rigid_body", noise, noise_seed, lambda: so_basis(n))
    if transport is not None:
        parameters["noise"] = transport.parameters()
    problem = IsospectralProblem(
        B=B,
        algebra=alg,
        noise=transport,
        kernel=ElementwiseLinear(-c),  # the same B, for the compiled fast path
        hamiltonian=hamiltonian,
        B_jvp=B_jvp,
        name=f"generalized rigid body on so({n})",
        parameters=parameters,
    )
    return problem, W_init
