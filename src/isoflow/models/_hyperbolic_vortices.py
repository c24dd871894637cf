r"""Point vortices on the hyperbolic plane (paper, Section 3.4), a Lie–Poisson system on
:math:`(\mathfrak{sl}(2,\mathbb{R})^*)^N \cong (\mathbb{R}^3, \times_L)^N`.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .._errors import NotInSpaceError, ParameterError
from ..algebras.sl2_vectors import L_DIAG, SL2Vectors
from ..kernels import PairwiseVortex
from ..problems import IsospectralProblem
from ._checks import check_separated, check_vortex_input

__all__ = ["PAPER_CONFIGS", "hyperbolic_vortices", "paper_vortex_config"]

Array = NDArray[Any]

_S2, _S3 = np.sqrt(2.0), np.sqrt(3.0)

#: The paper's two relative equilibria: exact positions (rows = vortices, the columns of the
#: paper's matrices, in order) and circulations. See :func:`paper_vortex_config`.
PAPER_CONFIGS: dict[int, tuple[tuple[tuple[float, float, float], ...], tuple[float, ...]]] = {
    1: (
        ((-0.5, _S3 / 2, _S2), (-0.5, -_S3 / 2, _S2), (1.0, 0.0, _S2)),
        (0.5317, 0.0761, 1.0),
    ),
    2: (
        ((13 / 5, 5 / 26, 363 / 130), (4.0, 1 / 8, 33 / 8), (3.0, 1 / 6, 19 / 6)),
        (0.0990, 0.8091, 1.0),
    ),
}


def paper_vortex_config(config: int) -> tuple[Array, Array]:
    r"""Positions ``(3, 3)`` and circulations ``(3,)`` of the paper's configuration 1 or 2.

    The paper prints 4-digit roundings; these are the exact points on
    :math:`x^2 + y^2 - z^2 = -1` they round:

    * 1 (equilateral relative equilibrium): :math:`(-\tfrac12, \tfrac{\sqrt3}{2}, \sqrt2)`,
      :math:`(-\tfrac12, -\tfrac{\sqrt3}{2}, \sqrt2)`, :math:`(1, 0, \sqrt2)`,
      :math:`\Gamma^1 = (0.5317, 0.0761, 1)`;
    * 2 (geodesic relative equilibrium): :math:`(\tfrac{13}{5}, \tfrac{5}{26},
      \tfrac{363}{130})`, :math:`(4, \tfrac18, \tfrac{33}{8})`, :math:`(3, \tfrac16,
      \tfrac{19}{6})`, :math:`\Gamma^2 = (0.0990, 0.8091, 1)`.

    Parameters
    ----------
    config : {1, 2}
        The configuration of the paper.

    Returns
    -------
    positions : ndarray, shape (3, 3)
    circulations : ndarray, shape (3,)

    Raises
    ------
    ParameterError
        ``config`` is not 1 or 2.
    """
    if config not in PAPER_CONFIGS:
        raise ParameterError(f"hyperbolic_vortices: config must be 1 or 2, got {config!r}")
    pos, circ = PAPER_CONFIGS[config]
    return np.array(pos, dtype=np.float64), np.array(circ, dtype=np.float64)


# ---- the model ----------------------------------------------------------------------------------
def _lorentz_gram(W: Array) -> Array:
    """``D_ij = w_i ._L w_j``, shape ``(*batch, N, N)``."""
    return np.einsum("...ik,...jk->...ij", W * L_DIAG, W)


def hyperbolic_vortices(
    config: int | None = None,
    *,
    positions: ArrayLike | None = None,
    circulations: ArrayLike | None = None,
    tol: float = 1e-8,
) -> tuple[IsospectralProblem, Array]:
    r"""Point vortices on the hyperbolic plane (hyperboloid model) and their initial state.

    Equations of motion as printed in the paper (eq. (PV_eq)), which define the dynamics:

    .. math::

        \dot w_i = -\frac1\pi \sum_{j \ne i} \Gamma_j\,
                   \frac{w_i \times_L w_j}{(w_i \cdot_L w_j)^2 - 1},
        \qquad
        H = -\frac{1}{4\pi} \sum_{i \ne j} \Gamma_i \Gamma_j
            \log\frac{w_i \cdot_L w_j + 1}{w_i \cdot_L w_j - 1},
        \qquad
        M = \sum_i \Gamma_i w_i .

    In the convention :math:`\dot w = [B(w), w]` of :class:`~isoflow.IsospectralProblem`, with
    the bracket :math:`[b, w] = -b \times_L w` of :class:`~isoflow.algebras.SL2Vectors`
    (the vector form of :math:`[\varphi(b), \varphi(w)]`), the ODE reads
    :math:`\dot w_i = w_i \times_L b_i` with

    .. math::

        B_i(w) = -\frac1\pi \sum_{j\ne i} \frac{\Gamma_j\, w_j}{(w_i\cdot_L w_j)^2 - 1}
               = -\frac{1}{\Gamma_i} L \nabla_i H .

    So the printed dynamics is the Lie–Poisson flow of :math:`-H` with weights
    :math:`1/\Gamma_i` in the Euclidean pairing of :class:`~isoflow.algebras.SL2Vectors`,
    i.e. ``from_hamiltonian`` with the gradient :math:`-\nabla_i H/\Gamma_i` (equivalently
    :math:`-2` times the Frobenius Lie–Poisson flow of ``H`` on :math:`2\times2` matrices with
    weights :math:`1/\Gamma_i`; corrected from the paper). ``B`` is a gradient, so IsoMP on this
    problem (the
    *hyperbolic midpoint*) is a Poisson map for the weighted product structure
    :math:`P(w) = \operatorname{diag}(-\tfrac{2}{\Gamma_i} L \hat w_i L)`. ``H`` and ``M`` are
    conserved (``H`` because :math:`\nabla_i H \cdot \dot w_i = 0` term by term, ``M`` by
    antisymmetry of the pair sum); each vortex stays on its hyperboloid (the Casimir
    :math:`w_i\cdot_L w_i`).

    Parameters
    ----------
    config : {1, 2}, optional
        The paper's relative equilibria (:func:`paper_vortex_config`); default 1 when no
        ``positions`` are given. Exclusive with ``positions``/``circulations``.
    positions : array_like, shape (*batch, N, 3), optional
        Vortex positions, one row per vortex, on the upper sheet :math:`z > 0` of
        :math:`x^2+y^2-z^2 = -1` within ``tol``; they are then rescaled onto it exactly
        (:math:`w \mapsto w/\sqrt{-w\cdot_L w}`).
    circulations : array_like, shape (N,), optional
        Vortex strengths :math:`\Gamma_i`, finite and nonzero (required with ``positions``).
    tol : float
        Accepted :math:`|w_i \cdot_L w_i + 1|` of user positions.

    Returns
    -------
    problem : IsospectralProblem
        On ``sl2_vectors(N)``, with ``hamiltonian``, exact ``B_jvp`` and the invariant
        ``"momentum"`` :math:`\sum_i \Gamma_i w_i` (shape ``(*batch, 3)``).
        ``problem.parameters``: ``config`` (or ``None``), ``circulations``, ``positions``.
    w0 : ndarray, shape (*batch, N, 3)

    Raises
    ------
    ShapeError, DtypeError, NonFiniteError
        Malformed ``positions``/``circulations``.
    ParameterError
        Unknown ``config``, zero circulation, ``config`` together with ``positions``, or
        ``positions`` without ``circulations``.
    NotInSpaceError
        A position off the hyperboloid by more than ``tol``, on the lower sheet, or two
        coinciding vortices.

    References
    ----------
    M. Viviani, *A minimal-variable symplectic method for isospectral flows*, Section 3.4.
    J. Montaldi, C. Nava-Gaxiola, *Point vortices on the hyperbolic plane*, J. Math. Phys. 55
    (2014) 102702.
    S. Hwang, S.-C. Kim, *Point vortices on hyperbolic sphere*, J. Geom. Phys. 59 (2009);
    *Relative equilibria of point vortices on the hyperbolic sphere*, J. Math. Phys. 54 (2013).

    Notes
    -----
    The vortices live on the upper sheet of the hyperboloid :math:`x^2 + y^2 - z^2 = -1`,
    :math:`z > 0` (a model of the hyperbolic plane), with the Lorentzian products
    :math:`a \cdot_L b = a_1 b_1 + a_2 b_2 - a_3 b_3` and :math:`a \times_L b = 2 L (a \times b)`
    of :mod:`isoflow.algebras.sl2_vectors`. For two points on the sheet
    :math:`w_i \cdot_L w_j = -\cosh d_{ij} \le -1`, with :math:`d_{ij}` the hyperbolic distance.

    Examples
    --------
    >>> import isoflow as iso
    >>> prob, w0 = iso.models.hyperbolic_vortices(config=1)
    >>> sol = iso.solve(prob, iso.IsoMP(), y0=w0, dt=0.01, t1=1.0)
    """
    model = "hyperbolic_vortices"
    if positions is None:
        if circulations is not None:
            raise ParameterError(f"{model}: circulations given without positions")
        cfg = 1 if config is None else config
        pos, circ = paper_vortex_config(cfg)
    else:
        if config is not None:
            raise ParameterError(f"{model}: give either config or positions, not both")
        if circulations is None:
            raise ParameterError(f"{model}: positions need circulations")
        cfg = None
        pos, circ = check_vortex_input(positions, circulations, model)
    q = np.einsum("...i,...i->...", pos * L_DIAG, pos)
    off = float(np.max(np.abs(q + 1.0)))
    if off > tol:
        raise NotInSpaceError(
            f"{model}: positions must lie on the hyperboloid x^2 + y^2 - z^2 = -1; the largest "
            f"|w.L w + 1| is {off:.3e} > tol = {tol:.1e} (rescale by 1/sqrt(z^2 - x^2 - y^2))",
            distance=off,
            tolerance=tol,
        )
    if np.any(pos[..., 2] <= 0):
        raise NotInSpaceError(
            f"{model}: positions must lie on the upper sheet z > 0 of the hyperboloid",
            distance=float(np.max(np.maximum(-pos[..., 2], 0.0))),
            tolerance=0.0,
        )
    w_init = pos / np.sqrt(-q)[..., None]
    check_separated(_lorentz_gram(w_init), -1.0, model, "w_i ._L w_j")
    N = w_init.shape[-2]
    G = circ.copy()
    G.setflags(write=False)
    off_diag = ~np.eye(N, dtype=bool)
    inv_pi = 1.0 / np.pi

    def _kernel(W: Array) -> tuple[Array, Array, Array]:
        D = _lorentz_gram(W)
        den = np.where(off_diag, (D - 1.0) * (D + 1.0), 1.0)
        K = np.where(off_diag, G / den, 0.0)  # K_ij = G_j / (D_ij^2 - 1)
        return D, den, K

    def B(W: Array) -> Array:
        _, _, K = _kernel(W)
        return -inv_pi * np.einsum("...ij,...jk->...ik", K, W)

    def B_jvp(W: Array, dW: Array) -> Array:
        D, den, K = _kernel(W)
        dD = np.einsum("...ik,...jk->...ij", dW * L_DIAG, W)
        dD = dD + np.swapaxes(dD, -1, -2)
        dK = np.where(off_diag, -2.0 * G * D * dD / (den * den), 0.0)
        return -inv_pi * (
            np.einsum("...ij,...jk->...ik", dK, W) + np.einsum("...ij,...jk->...ik", K, dW)
        )

    def hamiltonian(W: Array) -> Array:
        D = _lorentz_gram(W)
        Ds = np.where(off_diag, D, -2.0)
        terms = np.where(off_diag, np.outer(G, G) * np.log((Ds + 1.0) / (Ds - 1.0)), 0.0)
        return -np.sum(terms, axis=(-2, -1)) / (4.0 * np.pi)

    def momentum(W: Array) -> Array:
        return np.einsum("i,...ik->...k", G, W)

    problem = IsospectralProblem(
        B=B,
        algebra=SL2Vectors(N),
        hamiltonian=hamiltonian,
        B_jvp=B_jvp,
        invariants={"momentum": momentum},
        name=f"point vortices on the hyperbolic plane (N = {N})",
        kernel=PairwiseVortex(G, "hyperbolic"),  # the same B, for the compiled fast paths
        parameters={"config": cfg, "circulations": G, "positions": w_init.copy()},
    )
    return problem, w_init
