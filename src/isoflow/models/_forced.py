r"""Dissipation, forcing and their budgets for the vorticity models on the sphere.

Shared by :func:`isoflow.models.euler_sphere` and :func:`isoflow.models.qg_sphere`: the model
keywords (``viscosity``, ``hyperviscosity``, ``drag``, ``forcing``) become a
:class:`~isoflow.sphere.SphereDissipation` and forcing terms of the problem (integrated by
:class:`~isoflow.Strang`), and the budgets become diagnostics of the saved states. The state of
both models is an absolute (potential) vorticity :math:`Q = W + F` with the planetary part
:math:`F` (:func:`~isoflow.models.coriolis_matrix`); dissipation acts on the relative part
:math:`W = Q - F`, so :math:`F` is the state the linear part relaxes to, which the split step
applies as the steady forcing :math:`-LF = c_1 F` (:math:`F` is a degree-one harmonic).

Budgets (derivations in ``docs/theory/forced.rst``), with the energy
:math:`E = \frac12\sum_{lm}\omega_{lm}^2/\lambda_l`, :math:`\lambda_l = l(l+1)`, and the
enstrophy :math:`Z = \frac12\sum_{lm}\omega_{lm}^2` of the relative vorticity:

* ``energy_dissipation`` :math:`D_E = \sum_l c_l E_l`, ``enstrophy_dissipation``
  :math:`D_Z = \sum_l c_l Z_l` (the rates of loss to the linear part);
* ``energy_injection``, ``enstrophy_injection``: the rates of a steady forcing
  (:math:`\sum f_{lm}\omega_{lm}/\lambda_l` and :math:`\sum f_{lm}\omega_{lm}`) plus the mean
  rates of the noise (:math:`\frac12\sum\sigma^2/\lambda` and :math:`\frac12\sum\sigma^2`);
* ``energy_transfer``: the spectrum :math:`T_l = \sum_m \omega_{lm}\dot\omega^{B}_{lm}/\lambda_l`
  of the bracket's tendency (it sums to zero: the bracket conserves the energy);
* ``energy_spectrum``, ``enstrophy_spectrum``: :math:`E_l = \sum_m\omega_{lm}^2/\lambda_l`,
  :math:`Z_l = \sum_m\omega_{lm}^2` (so :math:`\sum_l E_l = 2E`).

So :math:`dE/dt = \text{injection} - D_E` on average, term by term in the spectrum.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .._errors import ParameterError
from ..sphere import degree_order, to_coefficients
from ..sphere._dissipation import SphereDissipation, band_forcing, degree_rates
from ..splitting import Forcing, StochasticForcing

__all__ = ["SplitSpec", "sphere_split"]

Array = NDArray[Any]


@dataclass(frozen=True)
class SplitSpec:
    """The split parts of a sphere model and what its diagnostics need."""

    linear_part: SphereDissipation | None
    forcing: tuple[Forcing | StochasticForcing, ...]
    user_forcing: tuple[Forcing | StochasticForcing, ...]
    parameters: dict[str, Any]

    @property
    def active(self) -> bool:
        return self.linear_part is not None or bool(self.forcing)


def _forcing_terms(forcing: Any, N: int, model: str) -> tuple[Forcing | StochasticForcing, ...]:
    """``forcing`` as terms: ``None``, a matrix (a steady forcing of the relative vorticity),
    an :class:`~isoflow.Forcing`, a :class:`~isoflow.StochasticForcing` or a sequence."""
    if forcing is None:
        return ()
    if isinstance(forcing, (Forcing, StochasticForcing)):
        return (forcing,)
    if isinstance(forcing, (list, tuple)) and all(
        isinstance(f, (Forcing, StochasticForcing)) for f in forcing
    ):
        return tuple(forcing)
    arr = np.asarray(forcing)
    if arr.dtype.kind in "iufc" and arr.shape == (N, N):
        return (Forcing(arr),)
    raise ParameterError(
        f"{model}: forcing must be None, an ({N}, {N}) matrix (a steady forcing), an "
        "iso.Forcing, an iso.StochasticForcing (e.g. iso.sphere.band_forcing(...)) or a list "
        f"of them, got {type(forcing).__name__}"
    )


def _describe_forcing(terms: Sequence[Forcing | StochasticForcing]) -> list[dict[str, Any]]:
    out: list[dict[str, Any]] = []
    for f in terms:
        if isinstance(f, StochasticForcing):
            modes = np.asarray(f.modes).reshape(-1)
            sigma = np.broadcast_to(np.asarray(f.sigma, dtype=float), modes.shape)
            rms = float(np.sqrt(np.mean(sigma**2)))
            out.append({"kind": "stochastic", "modes": int(modes.size), "sigma_rms": rms,
                        "seed": int(f.seed)})  # fmt: skip
        else:
            out.append({"kind": "time-dependent" if f.time_dependent else "steady",
                        "norm": float(np.linalg.norm(np.asarray(f.pattern)))})  # fmt: skip
    return out


def sphere_split(
    N: int,
    *,
    viscosity: float,
    hyperviscosity: tuple[float, float] | None,
    drag: float,
    forcing: Any,
    planetary: Array,
    model: str,
    forcing_band: tuple[int, int] | None = None,
    energy_rate: float | None = None,
    forcing_seed: int | None = None,
    energy_weight: Callable[[Array], Array] | None = None,
) -> SplitSpec:
    r"""The linear part and forcing terms of a sphere model (none when all are off).

    ``energy_weight(E)``, for unit harmonics ``E`` (``(r, N, N)``), is the model's energy of
    each (:math:`1/\lambda_l` for Euler, the default): the band forcing's amplitude is chosen
    so that its mean injection of *this* energy is ``energy_rate``.

    Raises
    ------
    ParameterError
        Negative or non-finite coefficients, ``p < 1``, a forcing of the wrong kind (the
        patterns themselves are checked by the problem: outside the space, not finite).
    """
    c = degree_rates(N, viscosity, hyperviscosity, drag)
    user = _forcing_terms(forcing, N, model)
    if forcing_band is not None:
        try:
            lf, dl = forcing_band
        except (TypeError, ValueError):
            raise ParameterError(
                f"{model}: forcing_band must be a pair (lf, dl), got {forcing_band!r}"
            ) from None
        rate = 1.0 if energy_rate is None else energy_rate
        seed = 0 if forcing_seed is None else forcing_seed
        user = (*user, band_forcing(N, lf, dl, energy_rate=rate, seed=seed))
    elif energy_rate is not None or forcing_seed is not None:
        raise ParameterError(f"{model}: energy_rate and forcing_seed go with forcing_band")
    dissipative = bool(np.any(c > 0))
    if not dissipative and not user:
        return SplitSpec(None, (), (), {})
    lin = SphereDissipation(N, c)
    if forcing_band is not None and energy_weight is not None:
        user = (*user[:-1], _rescaled(user[-1], lin, energy_weight, rate))
    terms: list[Forcing | StochasticForcing] = list(user)
    if dissipative and np.any(planetary != 0):  # relax to the planetary vorticity, not to 0
        terms.append(Forcing(c[1] * planetary))
    params: dict[str, Any] = {"viscosity": float(viscosity), "drag": float(drag)}
    if hyperviscosity is not None:
        params["hyperviscosity"] = [float(hyperviscosity[0]), float(hyperviscosity[1])]
    if user:
        params["forcing"] = _describe_forcing(user)
    if forcing_band is not None:
        params.update(forcing_band=[int(v) for v in forcing_band], energy_rate=float(rate))
        params["forcing_seed"] = int(seed)
    return SplitSpec(lin, tuple(terms), user, params)


def _rescaled(
    band: Forcing | StochasticForcing,
    lin: SphereDissipation,
    energy_weight: Callable[[Array], Array],
    rate: float,
) -> StochasticForcing:
    r"""``band`` with the one amplitude whose mean injection of the model's energy is ``rate``:
    :math:`\frac12\sigma^2\sum_j w_j = \varepsilon` with :math:`w_j` the energy of mode
    ``j`` (Itô)."""
    assert isinstance(band, StochasticForcing)
    modes, _ = noise_modes(band)
    weights = np.asarray(energy_weight(lin.modes(modes)), dtype=float)
    sigma = np.sqrt(2.0 * float(rate) / float(np.sum(weights)))
    return StochasticForcing(modes, sigma, band.seed)


class _Coefficients:
    """The coefficients of a matrix function of the last states asked for (the diagnostics of
    one batch of saved states ask for them several times)."""

    def __init__(self, of: Callable[[Array], Array]) -> None:
        self.of = of
        self._last: tuple[Any, Array] | None = None

    def __call__(self, Q: Array) -> Array:
        if self._last is not None and self._last[0] is Q:
            return self._last[1]
        c = to_coefficients(self.of(np.asarray(Q)))
        self._last = (Q, c)
        return c


def budget_observables(
    N: int,
    spec: SplitSpec,
    relative: Callable[[Array], Array],
    stream: Callable[[Array], Array],
    tendency: Callable[[Array], Array],
    noise_weight: Callable[[Array], Array],
) -> dict[str, Callable[[Array], Array]]:
    r"""The spectra, dissipation, injection and transfer diagnostics of a sphere model (the
    problem's ``observables``: saved and drawn, no drift).

    ``relative(Q)`` is the relative (potential) vorticity :math:`q` of states ``Q``,
    ``stream(Q)`` their stream matrix :math:`\psi`, ``tendency(Q)`` the bracket's
    :math:`[B(Q), Q]`, ``noise_weight(modes)`` the energy :math:`\langle e_j, -A^{-1}e_j\rangle`
    of a unit of each mode (:math:`1/\lambda_l` for Euler). With :math:`E = -\frac12
    \sum\psi_{lm} q_{lm}` the energy and :math:`L` acting on :math:`q`:

    * ``energy_dissipation`` :math:`\sum c_l(-\psi_{lm}) q_{lm}`, ``enstrophy_dissipation``
      :math:`\sum c_l q_{lm}^2`;
    * ``energy_injection`` :math:`-\sum\psi_{lm}f_{lm}` plus the noise's mean
      :math:`\frac12\sum\sigma_j^2 \langle e_j, -A^{-1}e_j\rangle`;
      ``enstrophy_injection`` :math:`\sum q_{lm}f_{lm} + \frac12\sum\sigma_j^2`;
    * ``energy_transfer`` :math:`T_l = -\sum_m \psi_{lm}\dot q^{B}_{lm}` (sums to zero);
    * ``energy_spectrum`` :math:`\sum_m \lambda_l\psi_{lm}^2` (kinetic; the convention of
      :func:`isoflow.sphere.energy_spectrum`, summing to twice the kinetic energy),
      ``enstrophy_spectrum`` :math:`\sum_m q_{lm}^2`.
    """
    ls, _ = degree_order(N - 1)
    lam = ls * (ls + 1.0)
    q = _Coefficients(relative)
    psi = _Coefficients(stream)
    starts = np.arange(1, N) ** 2 - 1

    def per_degree(v: Array) -> Array:
        return np.add.reduceat(v, starts, axis=-1)

    out: dict[str, Callable[[Array], Array]] = {
        "energy_spectrum": lambda Q: per_degree(lam * psi(Q) ** 2),
        "enstrophy_spectrum": lambda Q: per_degree(q(Q) ** 2),
        "energy_transfer": lambda Q: per_degree(-psi(Q) * to_coefficients(tendency(np.asarray(Q)))),
    }
    if spec.linear_part is not None:
        c = spec.linear_part.degree_rates[ls]
        out["energy_dissipation"] = lambda Q: np.sum(-c * psi(Q) * q(Q), -1)
        out["enstrophy_dissipation"] = lambda Q: np.sum(c * q(Q) ** 2, -1)
    steady = [f for f in spec.user_forcing if isinstance(f, Forcing) and not f.time_dependent]
    noise = [f for f in spec.user_forcing if isinstance(f, StochasticForcing)]
    if steady or noise:
        fc = np.zeros(ls.size)
        for term in steady:
            fc = fc + to_coefficients(np.asarray(term.pattern).reshape(-1, N, N)).sum(0)
        mean_e = mean_z = 0.0
        for noisy in noise:
            modes, sigma = noise_modes(noisy)
            mean_e += 0.5 * float(np.sum(sigma**2 * noise_weight(modes)))
            mean_z += 0.5 * float(np.sum(sigma**2))
        out["energy_injection"] = lambda Q: np.sum(-fc * psi(Q), -1) + mean_e
        out["enstrophy_injection"] = lambda Q: np.sum(fc * q(Q), -1) + mean_z
    return out


def noise_modes(forcing: StochasticForcing) -> tuple[Array, Array]:
    """The modes and the amplitudes (one per mode) of a stochastic forcing."""
    modes = np.asarray(forcing.modes, dtype=np.int64).reshape(-1)
    sigma = np.broadcast_to(np.asarray(forcing.sigma, dtype=np.float64), modes.shape)
    return modes, sigma


def check_double_bracket(alpha: ArrayLike, model: str) -> float:
    """The double-bracket coefficient: a finite real number ``>= 0``."""
    a = alpha
    if isinstance(a, bool) or not isinstance(a, (int, float, np.integer, np.floating)):
        raise ParameterError(f"{model}: double_bracket must be a real number, got {a!r}")
    if not np.isfinite(a) or a < 0:
        raise ParameterError(
            f"{model}: double_bracket must be finite and >= 0 (a negative coefficient feeds "
            f"energy in), got {a!r}"
        )
    return float(a)
