r"""Classical Heisenberg / XXZ spins with a Zeeman field on a periodic square lattice.

The equations and what they conserve: the Notes of :func:`isoflow.models.spin_lattice`.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numba
import numpy as np
from numpy.typing import ArrayLike, NDArray

from .. import algebras
from .._errors import ParameterError, ShapeError
from .._seeds import generator
from ..kernels import CompiledB
from ..problems import IsospectralProblem
from ._checks import real_parameter
from ._llg import gilbert, thermal_noise

__all__ = ["spin_lattice", "spin_lattice_field", "spin_lattice_llg_field"]

Array = NDArray[Any]


@numba.njit(cache=True)
def spin_lattice_field(W, out, L1, L2, J, Jz, field):  # type: ignore[no-untyped-def]
    r"""``B_i = h - J sum_{j ~ i} D w_j`` on the periodic ``L1 x L2`` lattice, ``(N, 3)``.

    A numba function for one system (the compiled ``f`` of :func:`spin_lattice`'s kernel).

    Parameters
    ----------
    W : ndarray, shape (N, 3)
        Spins, site ``(a, b)`` in row ``a L2 + b``; ``N = L1 L2``.
    out : ndarray, shape (N, 3)
        Written with ``B``.
    L1, L2 : int
        The lattice size.
    J, Jz : float
        The coupling of the ``x`` and ``y`` components and that of the ``z`` component
        (``Jz = J (1 + anisotropy)``): ``B_i = h - (J s_x, J s_y, Jz s_z)`` with ``s`` the
        sum of the four neighbours of site ``i``.
    field : ndarray, shape (3,)
        The Zeeman field ``h``.
    """
    for a in range(L1):
        ap = a + 1 if a + 1 < L1 else 0
        am = a - 1 if a > 0 else L1 - 1
        for b in range(L2):
            bp = b + 1 if b + 1 < L2 else 0
            bm = b - 1 if b > 0 else L2 - 1
            i = a * L2 + b
            n1, n2, n3, n4 = ap * L2 + b, am * L2 + b, a * L2 + bp, a * L2 + bm
            sx = W[n1, 0] + W[n2, 0] + W[n3, 0] + W[n4, 0]
            sy = W[n1, 1] + W[n2, 1] + W[n3, 1] + W[n4, 1]
            sz = W[n1, 2] + W[n2, 2] + W[n3, 2] + W[n4, 2]
            out[i, 0] = field[0] - J * sx
            out[i, 1] = field[1] - J * sy
            out[i, 2] = field[2] - Jz * sz


@numba.njit(cache=True)
def spin_lattice_llg_field(W, out, L1, L2, J, Jz, field, lam):  # type: ignore[no-untyped-def]
    r"""``B_i = H_i + lam S_i x H_i`` with :math:`H_i` of :func:`spin_lattice_field` (Gilbert
    damping, :mod:`isoflow.models._llg`).

    Parameters
    ----------
    W, out, L1, L2, J, Jz, field
        As in :func:`spin_lattice_field`.
    lam : float
        The Gilbert damping :math:`\lambda`.
    """
    spin_lattice_field(W, out, L1, L2, J, Jz, field)
    gilbert(W, out, lam)


def _neighbour_sum(W: Array, L1: int, L2: int) -> Array:
    """Sum of the four neighbours of every site, ``(*batch, N, 3)`` (NumPy, for ``H``)."""
    G = W.reshape(*W.shape[:-2], L1, L2, 3)
    s = (
        np.roll(G, 1, axis=-3) + np.roll(G, -1, axis=-3)
        + np.roll(G, 1, axis=-2) + np.roll(G, -1, axis=-2)
    )  # fmt: skip
    return s.reshape(W.shape)


def spin_lattice(
    shape: tuple[int, int] = (16, 16),
    *,
    J: float = 1.0,
    anisotropy: float = 0.0,
    field: ArrayLike = (0.0, 0.0, 0.0),
    initial: str = "random",
    seed: int | None = 0,
    w0: ArrayLike | None = None,
    temperature: float = 0.0,
    damping: float = 0.0,
    noise_seed: int | None = None,
) -> tuple[IsospectralProblem, Array]:
    r"""Classical Heisenberg/XXZ spins with a Zeeman field on a periodic square lattice.

    The equations (Notes below):
    :math:`H = J \sum_{\langle ij\rangle} w_i \cdot D w_j - h\cdot\sum_i w_i`,
    :math:`D = \operatorname{diag}(1, 1, 1 + \Delta)`,
    :math:`\dot w_i = w_i \times \nabla_i H`, on :math:`(\mathbb{R}^3,\times)^N`,
    :math:`N = L_1 L_2`, site ``(a, b)`` at row ``a L_2 + b``.

    Parameters
    ----------
    shape : (int, int)
        Lattice size ``(L1, L2)``, each at least 3 (so that the four neighbours of a site are
        distinct sites).
    J : float
        Exchange coupling (``> 0`` antiferromagnetic).
    anisotropy : float
        :math:`\Delta`: the ``z`` coupling is :math:`J (1 + \Delta)` (XXZ).
    field : array_like, shape (3,)
        The Zeeman field ``h``.
    initial : {"random", "ferro"}
        Unit spins uniformly on the sphere (``seed``), or all along ``+z`` tilted by a small
        seeded perturbation (a spin wave around the ferromagnetic state).
    seed : int or None
        Seed of the initial data.
    w0 : array_like, optional
        Explicit initial spins ``(*batch, N, 3)`` (overrides ``initial``).
    temperature, damping : float
        Stochastic Landau–Lifshitz–Gilbert dynamics at temperature ``T >= 0`` (``k_B = 1``)
        with Gilbert damping :math:`\lambda \ge 0`,
        :math:`dS_i = -S_i \times (H_i\,dt + \sqrt{2\lambda T} \circ d\beta_i)
        - \lambda S_i \times (S_i \times H_i)\,dt`, :math:`H_i = -\nabla_i H`
        (:mod:`isoflow.models._llg`): the damping enters ``B``, the thermal field is site
        noise (integrate with :class:`~isoflow.StochasticIsoMP`). ``T > 0`` needs
        ``damping > 0``.
    noise_seed : int, optional
        Seed of the thermal noise (required when ``temperature > 0``).

    Returns
    -------
    problem : IsospectralProblem
        On ``so3_vectors(N)`` with the compiled field (``iso.CompiledB``) and ``hamiltonian``.
        The total spin (``(*batch, 3)``) is the invariant ``"total_spin"`` where the flow
        conserves it (:math:`\Delta = 0`, ``h = 0``, no damping or temperature), else the
        observable ``"total_spin"``, with the invariant ``"total_spin_along_field"``
        (:math:`S \cdot h / |h|`, :math:`\Delta = 0`) or ``"total_spin_z"`` (a field along
        ``z`` or none) where that part is conserved. With damping at ``T = 0`` the energy
        decreases: ``lyapunov`` is :math:`-H`.
    w0 : ndarray, shape (*batch, N, 3)

    Raises
    ------
    ParameterError, ShapeError
        A lattice side below 3, non-finite couplings or field, a field of the wrong shape, an
        unknown ``initial``.

    Notes
    -----
    The model is written against the public protocol only (a ``CompiledB`` field, an
    ``IsospectralProblem`` on :math:`(\mathbb{R}^3,\times)^N`), as a user would write it: its ``B``
    is given once, as a compiled function, and runs on every path (the NumPy path derives its
    ``B`` from it; the compiled loops call it directly).

    **Equations.** Spins :math:`w_i \in \mathbb{R}^3` sit on the sites ``i = (a, b)`` of an
    ``L_1 x L_2`` grid with periodic boundary conditions; :math:`\langle ij\rangle` runs over
    nearest-neighbour pairs (each once). With :math:`D = \operatorname{diag}(1, 1, 1 + \Delta)`
    and a field ``h``,

    .. math::

        H(w) = J \sum_{\langle ij\rangle} w_i \cdot D w_j \;-\; h \cdot \sum_i w_i ,
        \qquad
        \dot w_i = w_i \times \nabla_i H = w_i \times \Big(J \sum_{j \sim i} D w_j - h\Big),

    the Lie–Poisson flow on :math:`(\mathfrak{so}(3)^*)^N` in the pairing of
    :class:`~isoflow.algebras.SpinVectors` (:math:`\dot w_i = w_i \times \nabla_i H`). In the form
    :math:`\dot w = [B(w), w] = B(w) \times w` this is :math:`B_i = -\nabla_i H = h - J \sum_{j \sim
    i} D w_j`. ``J > 0`` is antiferromagnetic, ``J < 0`` ferromagnetic; :math:`\Delta = 0` is the
    isotropic Heisenberg model.

    Conserved: every :math:`|w_i|` (Casimirs), ``H``, and the total spin :math:`S = \sum_i w_i`
    when :math:`\Delta = 0` and :math:`h = 0`: :math:`\dot S = \sum_i w_i \times (J \sum_{j\sim
    i} D w_j - h)`, whose pair terms cancel for :math:`D = I` (and their :math:`z` components
    for the anisotropy along ``z``) and whose field term is :math:`-S \times h`. So
    :math:`S \cdot h` is conserved when :math:`\Delta = 0`, and :math:`S_z` when the field is
    along ``z`` (or zero). Gilbert damping lowers ``H``; damping and noise conserve no part of
    :math:`S`.

    Examples
    --------
    >>> import isoflow as iso
    >>> prob, w0 = iso.models.spin_lattice((8, 8), anisotropy=0.5, field=(0, 0, 0.3))
    >>> sol = iso.solve(prob, iso.IsoMP(), w0, dt=0.05, n_steps=20)
    """
    try:
        L1, L2 = (int(v) for v in shape)
    except (TypeError, ValueError):
        raise ParameterError(f"spin_lattice: shape must be two integers, got {shape!r}") from None
    if any(isinstance(v, bool) for v in shape) or min(L1, L2) < 3 or (L1, L2) != tuple(shape):
        raise ParameterError(
            f"spin_lattice: shape must be two integers >= 3 (periodic neighbours), got {shape!r}"
        )
    J = float(real_parameter(J, "J"))
    delta = float(real_parameter(anisotropy, "anisotropy"))
    h = real_parameter(field, "field")
    if h.shape != (3,):
        raise ShapeError(f"spin_lattice: field must have shape (3,), got {h.shape}")
    h = np.ascontiguousarray(h)
    h.setflags(write=False)
    N = L1 * L2
    alg = algebras.so3_vectors(N)
    rng = generator(seed, "spin_lattice: seed")
    if w0 is not None:
        w_init = np.array(alg.validate(w0, "w0"), copy=True)
        source = "user"
    elif initial == "random":
        g = rng.standard_normal((N, 3))
        w_init = g / np.linalg.norm(g, axis=-1, keepdims=True)
        source = "random"
    elif initial == "ferro":
        g = np.array([0.0, 0.0, 1.0]) + 0.1 * rng.standard_normal((N, 3))
        w_init = g / np.linalg.norm(g, axis=-1, keepdims=True)
        source = "ferro"
    else:
        raise ParameterError(f"spin_lattice: initial must be 'random' or 'ferro', got {initial!r}")
    D = np.array([1.0, 1.0, 1.0 + delta])

    def hamiltonian(W: Array) -> Array:
        # each bond once: half of the sum over sites of w_i . D (sum of the 4 neighbours)
        pair = 0.5 * J * np.sum(W * (D * _neighbour_sum(W, L1, L2)), axis=(-2, -1))
        return pair - np.sum(W, axis=-2) @ h

    def total_spin(W: Array) -> Array:
        return np.sum(W, axis=-2)

    T, lam, noise = thermal_noise("spin_lattice", temperature, damping, noise_seed)
    invariants, observables = _total_spin_diagnostics(total_spin, delta, h, lam > 0 or T > 0)
    if lam > 0:
        kernel = CompiledB(
            spin_lattice_llg_field, (L1, L2, J, J * (1.0 + delta), h, lam), name="spin_lattice_llg"
        )
    else:
        kernel = CompiledB(
            spin_lattice_field, (L1, L2, J, J * (1.0 + delta), h), name="spin_lattice"
        )
    problem = IsospectralProblem(
        algebra=alg,
        kernel=kernel,
        noise=noise,
        hamiltonian=hamiltonian,
        lyapunov=(lambda W: -hamiltonian(W)) if lam > 0 and T == 0 else None,
        invariants=invariants,
        observables=observables,
        name=f"spin lattice {L1}x{L2} (J = {J:g}, anisotropy = {delta:g})",
        parameters={
            "shape": (L1, L2),
            "J": J,
            "anisotropy": delta,
            "field": h.tolist(),
            "initial": source,
            "temperature": T,
            "damping": lam,
            "noise_seed": None if noise is None else noise.seed,
        },
    )
    return problem, w_init


def _total_spin_diagnostics(
    total_spin: Callable[[Array], Array], delta: float, h: Array, stochastic_or_damped: bool
) -> tuple[dict[str, Callable[[Array], Array]], dict[str, Callable[[Array], Array]]]:
    r"""``(invariants, observables)`` of the total spin :math:`S = \sum_i w_i`: what of it the
    flow conserves is an invariant, the rest an observable (saved, no drift).

    :math:`\dot S = -S \times h` plus pair terms that cancel for an isotropic coupling, and
    whose :math:`z` components cancel for the anisotropy along :math:`z`: all of :math:`S` is
    conserved for :math:`\Delta = 0, h = 0`; :math:`S \cdot h` for :math:`\Delta = 0`;
    :math:`S_z` for a field along :math:`z` (or none). Damping and noise conserve none.
    """
    if stochastic_or_damped:
        return {}, {"total_spin": total_spin}
    if delta == 0.0 and not np.any(h):
        return {"total_spin": total_spin}, {}
    if delta == 0.0:
        unit = h / np.linalg.norm(h)

        def along_field(W: Array) -> Array:
            return total_spin(W) @ unit

        return {"total_spin_along_field": along_field}, {"total_spin": total_spin}
    if h[0] == 0.0 and h[1] == 0.0:

        def z_component(W: Array) -> Array:
            return total_spin(W)[..., 2]

        return {"total_spin_z": z_component}, {"total_spin": total_spin}
    return {}, {"total_spin": total_spin}
