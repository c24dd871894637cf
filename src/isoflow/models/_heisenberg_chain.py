r"""The periodic Heisenberg spin chain on :math:`(\mathbb{R}^3, \times)^N` (paper, Section 3.3).

The equations and what they conserve: the docstring of :func:`isoflow.models.heisenberg_chain`.
"""

from __future__ import annotations

from typing import Any, Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .._errors import ParameterError
from .._seeds import generator
from ..algebras.spin import SpinVectors, dot
from ..kernels import SpinNeighbourSum
from ..problems import IsospectralProblem
from ._llg import thermal_noise

__all__ = ["heisenberg_chain", "paper_spin_curve"]

Array = NDArray[Any]


def paper_spin_curve(N: int) -> Array:
    r"""The paper's closed curve on :math:`S^2` sampled at ``x_i = i/N``, ``i = 0..N-1``.

    :math:`w(x) = (\cos 2\pi x^2 \sin 2\pi x^3,\ \sin 2\pi x^2 \sin 2\pi x^3,\ \cos 2\pi x^3)`;
    ``x = 1`` repeats ``x = 0`` (the north pole), so the curve is closed and the chain periodic.
    Shape ``(N, 3)``, unit vectors.
    """
    x = np.arange(N) / N
    a, b = 2.0 * np.pi * x**2, 2.0 * np.pi * x**3
    return np.stack([np.cos(a) * np.sin(b), np.sin(a) * np.sin(b), np.cos(b)], axis=-1)


def _neighbours(W: Array) -> Array:
    """``w_{i-1} + w_{i+1}`` along the particle axis, periodic (a new array)."""
    out = np.empty(W.shape, dtype=np.result_type(W, np.float64))
    out[..., 1:-1, :] = W[..., :-2, :] + W[..., 2:, :]
    out[..., 0, :] = W[..., -1, :] + W[..., 1, :]
    out[..., -1, :] = W[..., -2, :] + W[..., 0, :]
    return out


def heisenberg_chain(
    N: int = 100,
    *,
    initial: Literal["curve", "random"] = "curve",
    seed: int | np.random.Generator | None = None,
    w0: ArrayLike | None = None,
    temperature: float = 0.0,
    damping: float = 0.0,
    noise_seed: int | None = None,
) -> tuple[IsospectralProblem, Array]:
    r"""The periodic Heisenberg spin chain and its initial state.

    Equations (paper, eq. (HeiSC)):

    .. math::

        \dot w_i = w_i \times (w_{i-1} + w_{i+1}), \qquad
        H(w) = \sum_{i=1}^N w_i \cdot w_{i+1}, \qquad w_{N+1} = w_1,

    a spatial discretization (up to scaling) of the Landau–Lifshitz equation
    :math:`\dot w = w \times \partial_{xx} w` for a closed curve :math:`w: S^1 \to S^2`.
    With the Euclidean gradient :math:`\nabla_i H = w_{i-1} + w_{i+1}` this is
    :math:`\dot w_i = w_i \times \nabla_i H`, the Lie–Poisson flow on
    :math:`\mathfrak{so}(3)^{N*}` in the pairing of :class:`~isoflow.algebras.SpinVectors`.
    In the convention :math:`\dot w = [B(w), w] = B(w) \times w` of
    :class:`~isoflow.IsospectralProblem` this means

    .. math:: B_i(w) = -\nabla_i H = -(w_{i-1} + w_{i+1})

    (the sign corrected in ``docs/theory/method.rst``). IsoMP then solves
    :math:`w_k = x + \tfrac h2\, x \times B + \tfrac{h^2}{4} (B\cdot x) B` and
    :math:`w_{k+1} = x - \tfrac h2\, x \times B + \tfrac{h^2}{4}(B\cdot x) B`, ``B = B(x)``;
    :class:`~isoflow.SphericalMidpoint` is :math:`w_{k+1} = w_k + h\, m \times \nabla H(m)`.

    Conserved: :math:`|w_i|` (Casimirs), ``H``, and the total spin
    :math:`\sum_i w_i` (tracked as the invariant ``"momentum"``; linear, so conserved by
    IsoMP, the spherical and the classical midpoint up to rounding). With damping or a
    temperature only the :math:`|w_i|` are: ``"momentum"`` is then an observable, and with
    damping at ``T = 0`` the problem's ``lyapunov`` is :math:`-H`, which the damping raises.

    Parameters
    ----------
    N : int
        Number of spins, ``N >= 2`` (default 100, as in the paper).
    initial : {"curve", "random"}
        ``"curve"`` (default): the paper's closed curve, :func:`paper_spin_curve`.
        ``"random"``: independent uniformly distributed unit spins (``seed``), as in the
        paper's cost-per-step comparison.
    seed : int, Generator or None
        Seed for ``initial="random"``.
    w0 : array_like, optional
        Explicit initial spins, shape ``(*batch, N, 3)``, any lengths (overrides ``initial``).
    temperature, damping : float
        Stochastic Landau–Lifshitz–Gilbert dynamics at temperature ``T >= 0`` with Gilbert
        damping :math:`\lambda \ge 0` (as :func:`~isoflow.models.spin_lattice`): ``B`` gains
        :math:`\lambda w_i \times B_i` and every spin the thermal site noise
        :math:`\sqrt{2\lambda T}`; integrate with :class:`~isoflow.StochasticIsoMP`.
    noise_seed : int, optional
        Seed of the thermal noise (required when ``temperature > 0``).

    Returns
    -------
    problem : IsospectralProblem
        On ``so3_vectors(N)``, with ``hamiltonian``, the exact (linear) ``B_jvp`` and the
        invariant ``"momentum"`` (total spin, shape ``(*batch, 3)``).
    w0 : ndarray, shape (*batch, N, 3)

    References
    ----------
    M. Viviani, *A minimal-variable symplectic method for isospectral flows*, Section 3.3.
    R. I. McLachlan, K. Modin, O. Verdier, *A minimal-variable symplectic integrator on
    spheres*, Math. Comp. 86 (2017) (arXiv:1402.3334), Section on spin systems.

    Examples
    --------
    >>> import isoflow as iso
    >>> prob, w0 = iso.models.heisenberg_chain(N=100)
    >>> sol = iso.solve(prob, iso.IsoMP(), y0=w0, dt=0.1, t1=1.0)
    """
    if isinstance(N, bool) or not isinstance(N, (int, np.integer)):
        raise ParameterError(f"heisenberg_chain: N must be an integer, got {N!r}")
    if N < 2:
        raise ParameterError(f"heisenberg_chain: N must be >= 2, got {N}")
    N = int(N)
    alg = SpinVectors(N)
    if w0 is not None:
        w_init = np.array(alg.validate(w0, "w0"), copy=True)
        source = "user"
    elif initial == "curve":
        w_init = paper_spin_curve(N)
        source = "curve"
    elif initial == "random":
        g = generator(seed, "heisenberg_chain: seed").standard_normal((N, 3))
        w_init = g / np.linalg.norm(g, axis=-1, keepdims=True)
        source = "random"
    else:
        raise ParameterError(
            f"heisenberg_chain: initial must be 'curve' or 'random', got {initial!r}"
        )

    def B(W: Array) -> Array:
        return -_neighbours(W)

    def B_jvp(W: Array, dW: Array) -> Array:
        return -_neighbours(dW)

    def hamiltonian(W: Array) -> Array:
        return np.sum(dot(W, np.roll(W, -1, axis=-2)), axis=-1)

    def total_spin(W: Array) -> Array:
        return np.sum(W, axis=-2)

    T, lam, noise = thermal_noise("heisenberg_chain", temperature, damping, noise_seed)
    # the same B (with the Gilbert term), for the chain's fused compiled sweeps
    kernel = SpinNeighbourSum(-1.0, damping=lam)
    parameters: dict[str, Any] = {"N": N, "initial": source, "periodic": True}
    if lam > 0 or noise is not None:
        parameters |= {"temperature": T, "damping": lam, "noise_seed": getattr(noise, "seed", None)}
    problem = IsospectralProblem(
        B=None if lam > 0 else B,  # type: ignore[arg-type]
        algebra=alg,
        kernel=kernel,
        noise=noise,
        hamiltonian=hamiltonian,
        B_jvp=None if lam > 0 else B_jvp,
        lyapunov=(lambda W: -hamiltonian(W)) if lam > 0 and noise is None else None,
        # damping and noise move the total spin: saved, no drift
        invariants={} if lam > 0 or noise is not None else {"momentum": total_spin},
        observables={"momentum": total_spin} if lam > 0 or noise is not None else {},
        name=f"Heisenberg spin chain (N = {N})",
        parameters=parameters,
    )
    return problem, w_init
