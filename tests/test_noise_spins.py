"""Spins at finite temperature: stochastic Landau–Lifshitz–Gilbert by the stochastic midpoint.

Seeds and bounds are stated with each check; a bound of ``z`` standard errors (batch means of
a long time series) fails a correct implementation with probability about ``2 Phi(-z)``.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

import isoflow as iso
from isoflow._errors import ParameterError


def _langevin(x: float) -> float:
    return 1.0 / math.tanh(x) - 1.0 / x


def test_gilbert_damping_is_the_llg_double_bracket_with_its_sign() -> None:
    # B x S must be -S x H - lambda S x (S x H), H = -grad E; and E decreases along the flow
    lam = 0.4
    prob, w0 = iso.models.spin_lattice((3, 4), J=0.7, field=(0.1, 0.2, 0.5), damping=lam)
    undamped, _ = iso.models.spin_lattice((3, 4), J=0.7, field=(0.1, 0.2, 0.5))
    S = w0 * np.linspace(0.5, 2.0, 12)[:, None]  # lengths other than 1
    H = undamped.evaluate_B(S)
    rhs = -np.cross(S, H) - lam * np.cross(S, np.cross(S, H))
    assert np.allclose(np.cross(prob.evaluate_B(S), S), rhs, atol=1e-14)
    sol = iso.solve(prob, iso.StochasticIsoMP(), w0, dt=0.05, n_steps=200, progress=False)
    E = prob.hamiltonian(sol.ys)
    assert np.all(np.diff(E) < 1e-12) and E[-1] < E[0] - 1.0


@pytest.mark.parametrize("temperature", [0.5, 2.0])
def test_one_spin_in_a_field_follows_the_langevin_function(temperature: float) -> None:
    # J = 0: nine independent spins in b = (0, 0, 1), 8 members, damping 1, h = 0.01 (seed 7).
    # <S.b/|b|> = coth(x) - 1/x, x = |b| / T, within 4 standard errors of 20 batch means.
    prob, w0 = iso.models.spin_lattice(
        (3, 3), J=0.0, field=(0, 0, 1.0), temperature=temperature, damping=1.0, noise_seed=7,
        initial="ferro",
    )  # fmt: skip
    sol = iso.solve(
        prob, iso.StochasticIsoMP(), np.stack([w0] * 8), dt=0.01, n_steps=20000,
        save_every=10, progress=False,
    )  # fmt: skip
    assert "compiled" in sol.stats.runner
    mz = sol.ys[50:, ..., 2].mean(axis=2)  # after t = 5 (relaxation time 1)
    batches = mz[: mz.shape[0] // 20 * 20].reshape(20, -1, 8).mean(axis=1)
    est, se = batches.mean(), batches.std(ddof=1) / math.sqrt(batches.size)
    assert abs(est - _langevin(1.0 / temperature)) < 4 * se
    assert se < 0.01
    lengths = np.linalg.norm(sol.ys, axis=-1)
    assert float(np.abs(lengths - 1).max()) < 2e-12  # 20 000 steps, every path


def test_thermal_chain_keeps_every_spin_length_per_path() -> None:
    prob, w0 = iso.models.heisenberg_chain(40, temperature=0.5, damping=0.3, noise_seed=2)
    sol = iso.solve(prob, iso.StochasticIsoMP(), np.stack([w0] * 3), dt=0.02, n_steps=300,
                    progress=False)  # fmt: skip
    assert float(np.abs(np.linalg.norm(sol.ys, axis=-1) - 1).max()) < 1e-13
    assert float(np.abs(sol.ys[-1, 0] - sol.ys[-1, 1]).max()) > 0.1  # paths differ per member


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"temperature": -1.0, "damping": 0.1}, "temperature must be a finite number >= 0"),
        ({"temperature": 1.0, "damping": -0.1}, "damping must be a finite number >= 0"),
        ({"temperature": 1.0}, "needs damping > 0"),
        ({"temperature": 1.0, "damping": 0.1}, "noise_seed is required"),
    ],
)
def test_bad_temperature_damping_or_seed_are_one_line_errors(kwargs, message) -> None:  # type: ignore[no-untyped-def]
    for model in (iso.models.spin_lattice, iso.models.heisenberg_chain):
        with pytest.raises(ParameterError, match=message) as info:
            model(**kwargs)
        assert "\n" not in str(info.value)
