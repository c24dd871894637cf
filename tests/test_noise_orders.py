"""Strong order 1/2 and weak order 1 of the stochastic isospectral midpoint (issue 22).

The stochastic rigid body on so(3) (inertia of the paper, three non-commuting noise fields of
amplitude 1), ``M = 8000`` paths (seed 1) to ``T = 1``. Every coarse step uses the sum of the
increments of the fine steps it covers, so the coarse solutions lie on the Brownian paths of the
fine-step reference (``h_ref = 2^-8``). The slopes are fitted over ``h = 2^-3 .. 2^-6`` against
``h - h_ref`` (what the differences to the reference measure: ``C h - C h_ref``) and must be
within 0.15 of 1/2 (root-mean-square error) and of 1 (error of the mean of ``W_12 + W_13 +
W_23``). The weak errors are means of differences of size ``sqrt(h)`` per path, so their
standard errors are not small: the weak slope is a fit weighted by them, and its own standard
error must be below 0.075 (0.15 is then two of them; with 2000 paths it was 0.12 and the fitted
slope ranged over 0.8 .. 1.2 with the seed). About 30 s on a loaded machine: marked slow.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np
import pytest

import isoflow as iso
from isoflow import noise
from isoflow._compiled import stages

FINE = 2**8
M = 8000
_INCREMENTS = noise.brownian_increments(1, np.arange(M), 0, FINE, 3, 1.0 / FINE, truncation=None)


@dataclasses.dataclass(frozen=True)
class _OnTheFinePath(iso.StochasticIsoMP):
    """The stochastic midpoint on the increments of the fine path (``r`` fine steps a step)."""

    r: int = 1

    def step_data(self, problem: Any, request: Any) -> Any:
        ids = np.maximum(np.asarray(request.members), 0)
        steps = range(request.k0, request.k0 + request.nsteps)
        blocks = [_INCREMENTS[k * self.r : (k + 1) * self.r][:, ids].sum(axis=0) for k in steps]
        return np.stack(blocks)


stages.register(_OnTheFinePath, stages.stage_for(iso.StochasticIsoMP()))  # its compiled stage


@pytest.mark.slow
def test_strong_order_one_half_and_weak_order_one_on_the_same_brownian_paths() -> None:
    prob, W0 = iso.models.rigid_body(3, noise=1.0, noise_seed=1)
    Y0 = np.stack([W0] * M)

    def final(r: int) -> np.ndarray:
        method = _OnTheFinePath(solver=iso.FixedPoint(rtol=1e-13), r=r)
        sol = iso.solve(prob, method, Y0, dt=r / FINE, n_steps=FINE // r, save_every=FINE // r,
                        diagnostics=False, progress=False)  # fmt: skip
        assert "compiled" in sol.stats.runner
        return sol.ys[-1]

    ref = final(1)
    hs, strong, weak, weak_se = [], [], [], []
    for j in range(3, 7):
        Y = final(FINE // 2**j)
        hs.append(2.0**-j)
        strong.append(np.sqrt(np.mean(np.sum((Y - ref) ** 2, axis=(1, 2)))))
        diff = (Y - ref)[:, [0, 0, 1], [1, 2, 2]].sum(axis=1)
        weak.append(abs(diff.mean()))
        weak_se.append(diff.std() / np.sqrt(M))
    x = np.log(np.array(hs) - 1.0 / FINE)
    strong_order = np.polyfit(x, np.log(strong), 1)[0]
    relative_se = np.array(weak_se) / np.array(weak)  # the standard errors of log(weak)
    (weak_order, _), cov = np.polyfit(x, np.log(weak), 1, w=1 / relative_se, cov="unscaled")
    assert abs(strong_order - 0.5) < 0.15, strong_order
    assert np.sqrt(cov[0, 0]) < 0.075, (cov, weak, weak_se)
    assert abs(weak_order - 1.0) < 0.15, (weak_order, weak, weak_se)


@dataclasses.dataclass(frozen=True)
class _HeunOnTheFinePath(iso.StochasticHeun):
    """Stochastic Heun on the increments of the fine path (``r`` fine steps a step)."""

    r: int = 1

    step_data = _OnTheFinePath.step_data


def test_stochastic_heun_has_strong_order_one_half_and_drifts_off_the_casimirs() -> None:
    # 1000 of the paths above; Heun against its own fine-step solution, slope within 0.15 of
    # 1/2. Its Casimir drift at h = 2^-5 is far above rounding; the midpoint's, on the same
    # paths, at rounding.
    prob, W0 = iso.models.rigid_body(3, noise=1.0, noise_seed=1)
    Y0 = np.stack([W0] * 1000)

    def run(method: Any, r: int) -> Any:
        return iso.solve(prob, method, Y0, dt=r / FINE, n_steps=FINE // r, save_every=FINE // r,
                         progress=False)  # fmt: skip

    ref = run(_HeunOnTheFinePath(r=1), 1).ys[-1]
    hs, strong = [], []
    for j in range(3, 7):
        sol = run(_HeunOnTheFinePath(r=FINE // 2**j), FINE // 2**j)
        assert sol.stats.runner == "NumPy"
        hs.append(2.0**-j)
        strong.append(np.sqrt(np.mean(np.sum((sol.ys[-1] - ref) ** 2, axis=(1, 2)))))
    order = np.polyfit(np.log(np.array(hs) - 1.0 / FINE), np.log(strong), 1)[0]
    assert abs(order - 0.5) < 0.15, (order, strong)
    heun = run(_HeunOnTheFinePath(r=8), 8).diagnostics.casimir_drift
    midpoint = run(_OnTheFinePath(r=8), 8).diagnostics.casimir_drift
    assert float(np.min(heun)) > 1e-4, heun  # about 7e-3 (median), every path above 1e-3
    assert float(np.max(midpoint)) < 1e-13, midpoint
