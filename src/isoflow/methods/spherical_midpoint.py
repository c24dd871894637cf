r"""The spherical midpoint method (McLachlan, Modin, Verdier) on :math:`(\mathbb{R}^3,\times)^N`.

For a problem :math:`\dot w = [B(w), w]` on :class:`~isoflow.algebras.SpinVectors`, i.e.
:math:`\dot w_i = B_i(w) \times w_i`, one step is, for every particle ``i``,

.. math::

    w_{k+1} = w_k + h\, B(m) \times m, \qquad
    m_i = \sqrt{|w_{k,i}|\,|w_{k+1,i}|}\;
          \frac{w_{k,i} + w_{k+1,i}}{|w_{k,i} + w_{k+1,i}|}

(the paper's :math:`\sqrt{w}` are square roots of the norms). For :math:`B = -\nabla H`
(the flow :math:`\dot w_i = w_i \times \nabla_i H`) it is the method
:math:`w_{k+1} = w_k + h\, m \times \nabla H(m)` of the reference. It is second order,
symmetric, Lie–Poisson for the product structure of :math:`\mathfrak{so}(3)^N` for *every*
Hamiltonian, and conserves :math:`|w_i|` exactly, since :math:`w_{k+1} - w_k \perp m \parallel
w_k + w_{k+1}`.

Fixed-point formulation
-----------------------
The unknown is the plain average :math:`M = (w_k + w_{k+1})/2` (as for the classical midpoint),
the fixed point of

.. math::

    G(M) = w_k + \tfrac h2\, B(m) \times m, \qquad
    m_i = \sqrt{|w_{k,i}|\,|2 M_i - w_{k,i}|}\; \frac{M_i}{|M_i|},

and :math:`w_{k+1} = w_k + h\, B(m) \times m` with ``m`` from the accepted ``M``. The
contraction factor is :math:`\tfrac h2 \operatorname{Lip}(m \mapsto B(m)\times m)`, half of that
of iterating on :math:`w_{k+1}` directly. A particle with :math:`M_i = 0` (only possible for
``h |B| ~ 2`` or a particle at the origin) gets :math:`m_i = 0`.

References
----------
R. I. McLachlan, K. Modin, O. Verdier, *A minimal-variable symplectic integrator on spheres*,
Math. Comp. 86 (2017), 2325–2344 (arXiv:1402.3334, 2014).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, ClassVar, Literal

import numpy as np
from numpy.typing import NDArray

from .._errors import UnsupportedAlgebraError
from ..algebras.spin import SpinVectors, dot
from ..nonlinear import FixedPoint, FixedPointProblem, NonlinearSolver
from ..problems import IsospectralProblem
from ._base import Method, StepResult, check_implicit_options

__all__ = ["SphericalMidpoint"]

Array = NDArray[Any]


def spherical_point(W: Array, M: Array) -> Array:
    r"""The spherical midpoint ``m`` of ``W`` and ``2 M - W`` (``M`` the plain average).

    :math:`m_i = \sqrt{|w_i|\,|2M_i - w_i|}\, M_i / |M_i|` per particle (``0`` where
    :math:`M_i = 0`).
    """
    nw = np.sqrt(dot(W, W))
    V = 2.0 * M - W
    nv = np.sqrt(dot(V, V))
    nm = np.sqrt(dot(M, M))
    factor = np.sqrt(nw * nv) / np.where(nm > 0, nm, 1.0)
    return np.where(nm > 0, factor, 0.0)[..., None] * M


def _spherical_point_jvp(W: Array, M: Array, dM: Array) -> tuple[Array, Array]:
    r"""``m`` of :func:`spherical_point` and its derivative in ``M`` along ``dM``.

    With :math:`v = 2M - w`, :math:`s = \sqrt{|w||v|}`, :math:`u = M/|M|`:
    :math:`dm = ds\, u + s\,(dM - u (u\cdot dM))/|M|`,
    :math:`ds = \sqrt{|w|/|v|}\; (v\cdot dM)/|v|`.
    """
    nw = np.sqrt(dot(W, W))
    V = 2.0 * M - W
    nv = np.sqrt(dot(V, V))
    nm = np.sqrt(dot(M, M))
    ok = (nm > 0) & (nv > 0)
    nm_s = np.where(ok, nm, 1.0)
    nv_s = np.where(ok, nv, 1.0)
    s = np.sqrt(nw * nv)
    u = M / nm_s[..., None]
    ds = np.sqrt(nw / nv_s) * dot(V, dM) / nv_s
    udm = dot(u, dM)
    m = np.where(ok, s / nm_s, 0.0)[..., None] * M
    dm = ds[..., None] * u + (s / nm_s)[..., None] * (dM - udm[..., None] * u)
    return m, np.where(ok[..., None], dm, 0.0)


@dataclass(frozen=True)
class SphericalMidpoint(Method):
    """The spherical midpoint method (McLachlan–Modin–Verdier) for spin systems.

    Only defined on :class:`~isoflow.algebras.SpinVectors` (:math:`(\\mathbb{R}^3,\\times)^N`,
    ``iso.algebras.so3_vectors(N)``); other spaces raise :class:`UnsupportedAlgebraError`
    (a ``TypeError`` and an :class:`~isoflow.IsoflowError`).

    Parameters
    ----------
    solver : FixedPoint or Newton
        Nonlinear solver for the average ``M = (w_k + w_{k+1})/2`` (see the module docstring).
        Newton uses exact directional derivatives when the problem supplies ``B_jvp``, else
        finite differences.
    initial_guess : {"extrapolate", "state"}
        ``"state"`` starts at ``M = w_k``; ``"extrapolate"`` (default) reuses the previous
        step's offset ``M_{k-1} - w_{k-1}``, as :class:`~isoflow.IsoMP` does, which saves
        iterations (the same warm start for both makes cost comparisons fair).

    Examples
    --------
    >>> import isoflow as iso
    >>> prob, w0 = iso.models.heisenberg_chain(N=20)
    >>> sol = iso.solve(prob, iso.SphericalMidpoint(), y0=w0, dt=0.1, n_steps=10)
    """

    solver: NonlinearSolver = field(default_factory=FixedPoint)
    initial_guess: Literal["extrapolate", "state"] = "extrapolate"

    order: ClassVar[int] = 2
    implicit: ClassVar[bool] = True
    symmetric: ClassVar[bool] = True
    name: ClassVar[str] = "spherical midpoint"

    def __post_init__(self) -> None:
        check_implicit_options(self.solver, self.initial_guess)

    @staticmethod
    def _check(problem: IsospectralProblem) -> SpinVectors:
        alg = problem.algebra
        if not isinstance(alg, SpinVectors):
            raise UnsupportedAlgebraError(
                f"the spherical midpoint method is defined on (R^3, x)^N only "
                f"(iso.algebras.so3_vectors(N)), not on {alg.name}; use iso.IsoMP() instead"
            )
        return alg

    def stage_problem(self, problem: IsospectralProblem, W: Array, h: float) -> FixedPointProblem:
        """The fixed-point problem ``M = G(M)`` of one step from ``W``.

        Parameters
        ----------
        problem : IsospectralProblem
            The problem to advance, on :func:`~isoflow.algebras.so3_vectors`.
        W : ndarray, shape (*batch, N, 3)
            The state at the start of the step.
        h : float
            The step size.

        Returns
        -------
        FixedPointProblem

        Raises
        ------
        UnsupportedAlgebraError
            The problem is not on ``(R^3, x)^N``.
        """
        alg = self._check(problem)
        half = 0.5 * h

        def G(M: Array, mask: Array | None) -> tuple[Array, Array]:
            Wm = W if mask is None else W[mask]
            m = spherical_point(Wm, M)
            C = alg.bracket(problem.evaluate_B(m), m)
            return Wm + half * C, C

        jvp = None
        if problem.B_jvp is not None:

            def jvp(M: Array, dM: Array, mask: Array | None) -> Array:
                Wm = W if mask is None else W[mask]
                m, dm = _spherical_point_jvp(Wm, M, dM)
                B = problem.evaluate_B(m)
                dB = problem.evaluate_B_jvp(m, dm)
                return half * (alg.bracket(dB, m) + alg.bracket(B, dm))

        return FixedPointProblem(G=G, algebra=alg, scale=alg.norm(W), jvp=jvp)

    def init(self, problem: IsospectralProblem, y0: Array, h: float) -> Any:
        """Check the space; no state before the first step.

        Parameters
        ----------
        problem : IsospectralProblem
            The problem to advance, on :func:`~isoflow.algebras.so3_vectors`.
        y0 : ndarray, shape (*batch, N, 3)
            The initial state.
        h : float
            The step size.

        Returns
        -------
        None

        Raises
        ------
        UnsupportedAlgebraError
            The problem is not on ``(R^3, x)^N``.
        """
        self._check(problem)
        return None

    def step(
        self, problem: IsospectralProblem, y: Array, h: float, state: Any = None
    ) -> StepResult:
        """One spherical midpoint step.

        Parameters
        ----------
        problem : IsospectralProblem
            The problem to advance, on :func:`~isoflow.algebras.so3_vectors`.
        y : ndarray, shape (*batch, N, 3)
            The state at the start of the step.
        h : float
            The step size.
        state : object, optional
            ``(h, M_k - W_k)`` of the previous step, the warm start when
            ``initial_guess="extrapolate"`` and the step size is the same; ``None`` starts
            from ``y``.

        Returns
        -------
        StepResult

        Raises
        ------
        UnsupportedAlgebraError
            The problem is not on ``(R^3, x)^N``.
        """
        alg = self._check(problem)
        M0 = y
        if self.initial_guess == "extrapolate" and state is not None and state[0] == h:
            M0 = y + state[1]
        res = self.solver.solve(self.stage_problem(problem, y, h), M0)
        y_next = alg.project(y + h * res.aux)
        new_state = (h, res.gx - y) if self.initial_guess == "extrapolate" else None
        return StepResult.from_solve(y_next, res, new_state)
