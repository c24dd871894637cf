r"""Point vortices on the unit sphere as a Lie–Poisson system on
:math:`(\mathfrak{so}(3)^*)^N \cong (\mathbb{R}^3, \times)^N`."""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .._errors import NotInSpaceError, ParameterError
from ..algebras.spin import SpinVectors
from ..kernels import PairwiseVortex
from ..problems import IsospectralProblem
from ._checks import check_separated, check_vortex_input
from ._noise import transport_noise

__all__ = ["sphere_vortices"]

Array = NDArray[Any]


def _gram(W: Array) -> Array:
    """``D_ij = w_i . w_j``, shape ``(*batch, N, N)``."""
    return np.einsum("...ik,...jk->...ij", W, W)


def sphere_vortices(
    positions: ArrayLike | None = None,
    circulations: ArrayLike | None = None,
    *,
    tol: float = 1e-8,
    noise: float | ArrayLike | None = None,
    noise_seed: int | None = None,
) -> tuple[IsospectralProblem, Array]:
    r"""Point vortices on the unit sphere and their initial state.

    Convention (Kidambi–Newton 1998; Newton 2001, Section 4.2; radius ``R = 1``; a vortex with
    :math:`\Gamma > 0` turns the fluid counter-clockwise seen from outside the sphere):

    .. math::

        \dot x_i = \frac{1}{4\pi} \sum_{j\ne i} \Gamma_j\,
                   \frac{x_j \times x_i}{1 - x_i \cdot x_j},
        \qquad
        H = -\frac{1}{4\pi} \sum_{i<j} \Gamma_i\Gamma_j \log\bigl(2 (1 - x_i\cdot x_j)\bigr),
        \qquad
        M = \sum_i \Gamma_i x_i .

    (:math:`2(1 - x_i \cdot x_j) = |x_i - x_j|^2` is the squared chord length.) In the
    convention :math:`\dot x = [B(x), x] = B(x) \times x` of
    :class:`~isoflow.IsospectralProblem`,

    .. math::

        B_i(x) = \frac{1}{4\pi} \sum_{j \ne i} \frac{\Gamma_j\, x_j}{1 - x_i \cdot x_j}
               = \frac{1}{\Gamma_i} \nabla_i H,

    i.e. :math:`\Gamma_i \dot x_i = \nabla_i H \times x_i`: the Lie–Poisson flow of ``H`` with
    weights :math:`-1/\Gamma_i` in the Euclidean pairing of
    :class:`~isoflow.algebras.SpinVectors` (``from_hamiltonian`` with the gradient
    :math:`-\nabla_i H/\Gamma_i`), Poisson tensor
    :math:`P(x) = \operatorname{diag}(-\hat x_i/\Gamma_i)`. A ring of ``n`` equal vortices at
    colatitude :math:`\theta` rotates rigidly about the pole with angular velocity
    :math:`\Gamma (n-1)\cos\theta / (4\pi \sin^2\theta)` (Polvani–Dritschel 1993).

    Conserved: :math:`|x_i| = 1` (Casimirs, exactly preserved by IsoMP and the spherical
    midpoint), ``H``, and the momentum ``M`` (linear; preserved by IsoMP to rounding).

    Parameters
    ----------
    positions : array_like, shape (*batch, N, 3)
        Unit vectors (within ``tol``; then normalized exactly), one row per vortex, distinct.
    circulations : array_like, shape (N,)
        Vortex strengths, finite and nonzero.
    tol : float
        Accepted :math:`||x_i|^2 - 1|`.
    noise : float or array_like, optional
        Stratonovich transport noise (:class:`~isoflow.noise.TransportNoise`): a number
        :math:`\sigma` gives the three noise Hamiltonians :math:`\sigma \sum_j \Gamma_j
        e_a\cdot x_j` (fields :math:`\sigma e_a` on every vortex: the configuration turned
        about random axes, its relative geometry and ``H`` kept); an array ``(m, N, 3)``
        gives the fields. Integrate with :class:`~isoflow.StochasticIsoMP`.
    noise_seed : int, optional
        Seed of the noise's increments (required with ``noise``).

    Returns
    -------
    problem : IsospectralProblem
        On ``so3_vectors(N)``, with ``hamiltonian``, exact ``B_jvp`` and the invariant
        ``"momentum"`` (shape ``(*batch, 3)``; an observable with ``noise``, which turns it);
        ``parameters``: ``circulations``,
        ``positions``.
    x0 : ndarray, shape (*batch, N, 3)

    Raises
    ------
    ShapeError, DtypeError, NonFiniteError
        Malformed input.
    ParameterError
        Missing positions/circulations or a zero circulation.
    NotInSpaceError
        A position off the unit sphere by more than ``tol`` or two coinciding vortices.

    References
    ----------
    R. Kidambi, P. K. Newton, *Motion of three point vortices on a sphere*, Physica D 116
    (1998) 143–175.
    P. K. Newton, *The N-Vortex Problem: Analytical Techniques*, Springer (2001).
    L. M. Polvani, D. G. Dritschel, *Wave and vortex dynamics on the surface of a sphere*,
    J. Fluid Mech. 255 (1993) 35–64.

    Examples
    --------
    >>> import numpy as np, isoflow as iso
    >>> x = np.array([[1.0, 0, 0], [0, 1.0, 0], [0, 0, 1.0]])
    >>> prob, x0 = iso.models.sphere_vortices(positions=x, circulations=[1.0, 1.0, -0.5])
    >>> sol = iso.solve(prob, iso.IsoMP(), y0=x0, dt=0.01, t1=1.0)
    """
    model = "sphere_vortices"
    if positions is None or circulations is None:
        raise ParameterError(f"{model}: positions and circulations are both required")
    pos, circ = check_vortex_input(positions, circulations, model)
    sq = np.einsum("...i,...i->...", pos, pos)
    off = float(np.max(np.abs(sq - 1.0)))
    if off > tol:
        raise NotInSpaceError(
            f"{model}: positions must be unit vectors; the largest ||x|^2 - 1| is {off:.3e} "
            f"> tol = {tol:.1e}",
            distance=off,
            tolerance=tol,
        )
    x_init = pos / np.sqrt(sq)[..., None]
    check_separated(_gram(x_init), 1.0, model, "x_i . x_j")
    N = x_init.shape[-2]
    G = circ.copy()
    G.setflags(write=False)
    off_diag = ~np.eye(N, dtype=bool)
    c = 1.0 / (4.0 * np.pi)

    def _kernel(W: Array) -> tuple[Array, Array]:
        den = np.where(off_diag, 1.0 - _gram(W), 1.0)
        return den, np.where(off_diag, G / den, 0.0)  # K_ij = G_j / (1 - x_i.x_j)

    def B(W: Array) -> Array:
        _, K = _kernel(W)
        return c * np.einsum("...ij,...jk->...ik", K, W)

    def B_jvp(W: Array, dW: Array) -> Array:
        den, K = _kernel(W)
        dD = np.einsum("...ik,...jk->...ij", dW, W)
        dD = dD + np.swapaxes(dD, -1, -2)
        dK = np.where(off_diag, G * dD / (den * den), 0.0)
        return c * (np.einsum("...ij,...jk->...ik", dK, W) + np.einsum("...ij,...jk->...ik", K, dW))

    def hamiltonian(W: Array) -> Array:
        den = np.where(off_diag, 1.0 - _gram(W), 0.5)
        terms = np.where(off_diag, np.outer(G, G) * np.log(2.0 * den), 0.0)
        return -0.5 * c * np.sum(terms, axis=(-2, -1))

    def momentum(W: Array) -> Array:
        return np.einsum("i,...ik->...k", G, W)

    transport = transport_noise(
        "sphere_vortices", noise, noise_seed, lambda: np.repeat(np.eye(3)[:, None, :], N, axis=1)
    )
    parameters: dict[str, Any] = {"circulations": G, "positions": x_init.copy()}
    if transport is not None:
        parameters["noise"] = transport.parameters()
    problem = IsospectralProblem(
        B=B,
        algebra=SpinVectors(N),
        noise=transport,
        hamiltonian=hamiltonian,
        B_jvp=B_jvp,
        # transport noise moves M (the default fields turn it; the exact flow keeps |M|)
        invariants={"momentum": momentum} if transport is None else {},
        observables={} if transport is None else {"momentum": momentum},
        name=f"point vortices on the sphere (N = {N})",
        kernel=PairwiseVortex(G, "sphere"),  # the same B, for the compiled fast paths
        parameters=parameters,
    )
    return problem, x_init
