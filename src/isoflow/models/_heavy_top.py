r"""The heavy top: a rigid body with a fixed point in a uniform gravitational field.

State: the pair :math:`(\Gamma, M)` of :func:`~isoflow.algebras.se3_vectors` (shape ``(2, 3)``),
both in the body frame: :math:`\Gamma` the unit vector pointing *up* (against gravity),
:math:`M` the angular momentum. With the principal moments of inertia
:math:`I = \operatorname{diag}(I_1, I_2, I_3)` about the fixed point and the unit vector
:math:`\chi` from the fixed point towards the centre of mass (at distance :math:`l`), the
energy is

.. math::

    H(\Gamma, M) = \tfrac12\, M\cdot I^{-1}M + m g l\; \chi\cdot\Gamma,

and the Lie–Poisson equations on :math:`\mathfrak{se}(3)^*` (Marsden and Ratiu, Sec. 1.4) are

.. math::

    \dot\Gamma = \Gamma \times \Omega, \qquad
    \dot M = M \times \Omega + m g l\; \Gamma \times \chi, \qquad \Omega = I^{-1} M,

the isospectral flow :math:`\dot X = [B, X]` of the dual vectors with
:math:`B = -(\Omega,\ m g l\,\chi)`. Casimirs: :math:`|\Gamma|^2` and :math:`M\cdot\Gamma`
(the angular momentum about the vertical); the energy is conserved, and two tops have a fourth
integral:

* **Lagrange** (:math:`I_1 = I_2`, :math:`\chi = e_3`): the spin :math:`M_3` about the symmetry
  axis;
* **Kovalevskaya** (:math:`I_1 = I_2 = 2 I_3`, :math:`\chi = e_1`): with :math:`c = m g l/I_3`,

  .. math::

      K = (\Omega_1^2 - \Omega_2^2 - c\,\Gamma_1)^2 + (2\Omega_1\Omega_2 - c\,\Gamma_2)^2 .

Units: any consistent set; in SI, moments of inertia in kg m², :math:`m g l` in N m (J),
:math:`M` in kg m² s⁻¹ (J s), time in s; :math:`\Gamma` and :math:`\chi` are unit vectors.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .._errors import ParameterError, ShapeError
from ..algebras import se3_vectors
from ..kernels import CompiledB
from ..problems import IsospectralProblem
from ._checks import real_parameter

__all__ = ["TOPS", "heavy_top"]

Array = NDArray[Any]

#: The tops: name -> default moments of inertia, centre-of-mass direction, initial ``Omega``
#: and initial ``Gamma`` (a tilted, fast-spinning Lagrange top that nutates; a Kovalevskaya top
#: off its special solutions; a top without symmetry, which is chaotic).
TOPS: dict[str, dict[str, tuple[float, float, float]]] = {
    "lagrange": {
        "inertia": (1.0, 1.0, 0.5),
        "center": (0.0, 0.0, 1.0),
        "omega": (0.4, -0.2, 6.0),
        "gamma": (0.0, 0.5, 0.8660254037844386),
    },
    "kovalevskaya": {
        "inertia": (2.0, 2.0, 1.0),
        "center": (1.0, 0.0, 0.0),
        "omega": (0.6, -0.3, 1.2),
        "gamma": (0.36, 0.48, 0.8),
    },
    "general": {
        "inertia": (1.0, 1.6, 2.2),
        "center": (0.3, -0.2, 0.9327379053088815),
        "omega": (1.0, 0.5, 1.5),
        "gamma": (0.6, 0.0, 0.8),
    },
}


def _vector(value: ArrayLike, what: str) -> Array:
    v = real_parameter(value, f"heavy_top: {what}")
    if v.shape != (3,):
        raise ShapeError(f"heavy_top: {what} must have 3 components, got shape {v.shape}")
    return v


def _unit(value: ArrayLike, what: str) -> Array:
    v = _vector(value, what)
    norm = float(np.linalg.norm(v))
    if norm == 0.0:
        raise ParameterError(f"heavy_top: {what} must be a nonzero vector (it is normalized)")
    return v / norm


def _check_top(top: str, inertia: Array, center: Array) -> None:
    """The symmetry that gives the Lagrange and Kovalevskaya tops their fourth integral."""
    I1, I2, I3 = inertia
    if top == "lagrange" and not (I1 == I2 and np.array_equal(center, [0.0, 0.0, 1.0])):
        raise ParameterError(
            f"heavy_top: a Lagrange top needs I1 == I2 and the centre of mass on e3, got "
            f"inertia {inertia.tolist()}, center {center.tolist()} (use top='general')"
        )
    if top == "kovalevskaya" and not (
        I1 == I2 == 2.0 * I3 and np.array_equal(center, [1.0, 0.0, 0.0])
    ):
        raise ParameterError(
            f"heavy_top: a Kovalevskaya top needs I1 == I2 == 2 I3 and the centre of mass on "
            f"e1, got inertia {inertia.tolist()}, center {center.tolist()} (use top='general')"
        )


def heavy_top(
    top: str = "lagrange",
    *,
    inertia: ArrayLike | None = None,
    center: ArrayLike | None = None,
    mgl: float = 1.0,
    M0: ArrayLike | None = None,
    Gamma0: ArrayLike | None = None,
) -> tuple[IsospectralProblem, Array]:
    r"""The heavy top (module docstring) and its initial state ``(Gamma0, M0)``.

    Parameters
    ----------
    top : {"lagrange", "kovalevskaya", "general"}
        Which top: the defaults of :data:`TOPS` for the parameters not given; a Lagrange or
        Kovalevskaya top keeps its symmetry (``inertia`` and ``center`` are checked) and adds its
        fourth integral to the invariants.
    inertia : array_like of 3 floats, optional
        Principal moments of inertia :math:`(I_1, I_2, I_3)` about the fixed point [kg m²],
        positive.
    center : array_like of 3 floats, optional
        Direction :math:`\chi` from the fixed point to the centre of mass in the body frame
        (normalized).
    mgl : float
        Mass times gravitational acceleration times the distance of the centre of mass from the
        fixed point [N m], ``>= 0`` (``0``: Euler's free top).
    M0 : array_like of 3 floats, optional
        Initial body angular momentum [kg m² s⁻¹]; default :math:`I\Omega_0` with the top's
        :math:`\Omega_0` of :data:`TOPS` [s⁻¹].
    Gamma0 : array_like of 3 floats, optional
        Initial upward vertical in the body frame (normalized).

    Returns
    -------
    problem : IsospectralProblem
        On ``se3_vectors()`` with the compiled kernel ``CompiledB(heavy_top field)``,
        ``hamiltonian`` :math:`H`, ``invariants``: ``"M3"`` (Lagrange) or ``"kovalevskaya"``
        (:math:`K`), and ``parameters``: ``top, inertia, center, mgl``.
    y0 : ndarray, shape (2, 3)
        ``(Gamma0, M0)``.

    Raises
    ------
    ParameterError
        Unknown ``top``, non-positive moments, negative ``mgl``, a zero direction, or a
        Lagrange/Kovalevskaya top without its symmetry.
    ShapeError, DtypeError, NonFiniteError
        A vector parameter that is not 3 finite real numbers.

    References
    ----------
    J. E. Marsden, T. S. Ratiu, *Introduction to Mechanics and Symmetry*, 2nd ed. (1999),
    Sec. 1.4 and 14.7. S. Kovalevskaya, Acta Math. 12 (1889) 177–232.

    Examples
    --------
    >>> import numpy as np, isoflow as iso
    >>> prob, y0 = iso.models.heavy_top("kovalevskaya")
    >>> sol = iso.solve(prob, iso.IsoMP(), y0, dt=0.01, n_steps=500)
    >>> bool(sol.diagnostics.casimir_drift < 1e-12)
    True
    """
    if not isinstance(top, str) or top not in TOPS:
        raise ParameterError(f"heavy_top: top must be one of {', '.join(TOPS)}, got {top!r}")
    defaults = TOPS[top]
    I = _vector(defaults["inertia"] if inertia is None else inertia, "inertia")  # noqa: E741
    if np.any(I <= 0):
        raise ParameterError(f"heavy_top: the moments of inertia must be positive, got {I}")
    chi = _unit(defaults["center"] if center is None else center, "center")
    weight_ = real_parameter(mgl, "heavy_top: mgl")
    if weight_.ndim != 0 or float(weight_) < 0:
        raise ParameterError(f"heavy_top: mgl must be a number >= 0, got {mgl!r}")
    weight = float(weight_)
    _check_top(top, I, chi)
    m0 = I * np.asarray(defaults["omega"]) if M0 is None else _vector(M0, "M0")
    g0 = _unit(defaults["gamma"] if Gamma0 is None else Gamma0, "Gamma0")
    alg = se3_vectors()
    inv_inertia = np.ascontiguousarray(1.0 / I)
    gravity = np.ascontiguousarray(weight * chi)

    def hamiltonian(Y: Array) -> Array:
        G, M = alg.split(np.asarray(Y))
        return 0.5 * np.sum(M * M * inv_inertia, axis=-1) + G @ gravity

    invariants: dict[str, Callable[[Array], Array]] = {}
    if top == "lagrange":
        invariants["M3"] = lambda Y: np.asarray(Y)[..., 1, 2]
    elif top == "kovalevskaya":
        c = weight / I[2]

        def kovalevskaya(Y: Array) -> Array:
            G, M = alg.split(np.asarray(Y))
            w1, w2 = M[..., 0] / I[0], M[..., 1] / I[1]
            return (w1 * w1 - w2 * w2 - c * G[..., 0]) ** 2 + (2 * w1 * w2 - c * G[..., 1]) ** 2

        invariants["kovalevskaya"] = kovalevskaya
    from .._kernel_fields import heavy_top as field

    problem = IsospectralProblem(
        algebra=alg,
        kernel=CompiledB(field, (inv_inertia, gravity), name="heavy_top_field"),
        hamiltonian=hamiltonian,
        invariants=invariants,
        name=f"heavy top ({top})",
        parameters={
            "top": top, "inertia": I.tolist(), "center": chi.tolist(), "mgl": weight,
        },
    )  # fmt: skip
    return problem, alg.pair(g0, m0)
