"""
Noise that keeps the structure: a stochastic rigid body and thermal spins
=========================================================================

Transport noise ``Σ [B_i(W), W] ∘ dβ_i`` moves the state of a Lie–Poisson system along its
coadjoint orbit, so every Casimir stays put on every path. The stochastic isospectral midpoint
(:class:`isoflow.StochasticIsoMP`) keeps them to rounding; stochastic Heun
(:class:`isoflow.StochasticHeun`), on the same Brownian increments, drifts off them. At finite
temperature the same construction gives stochastic Landau–Lifshitz–Gilbert dynamics that keep
every ``|S_i|`` (see :doc:`/theory/stochastic`).
"""

import os

import numpy as np
from matplotlib.figure import Figure

import isoflow as iso

QUICK = os.environ.get("ISOFLOW_DOCS_QUICK") == "1"
paths, T = (100, 5.0) if QUICK else (400, 20.0)
h = 0.02
prob, W0 = iso.models.rigid_body(3, noise=0.5, noise_seed=1)  # three random torques
Y0 = np.stack([W0] * paths)
mid = iso.solve(prob, iso.StochasticIsoMP(), Y0, dt=h, t1=T, save_every=5)
heun = iso.solve(prob, iso.StochasticHeun(), Y0, dt=h, t1=T, save_every=5)
print(f"midpoint: {mid.stats.runner}; Heun: {heun.stats.runner}")

# %%
# A few paths of the angular momentum ``(W_23, W_13, W_12)`` stay on the sphere ``|W| =
# const`` (the Casimir of so(3)); the energy spreads over the ensemble, its mean with the
# standard error from :func:`isoflow.ensemble.ensemble_statistics`.

energy = iso.ensemble.ensemble_statistics(mid, prob.hamiltonian)
fig = Figure(figsize=(11, 3.8), layout="constrained")
ax_p, ax_e, ax_c = fig.subplots(1, 3)
for j in range(3):
    ax_p.plot(mid.ts, mid.ys[:, j, 1, 2], lw=0.8, label=f"path {j}: W_23")
ax_p.set(xlabel="t", title="a few paths")
ax_p.legend(fontsize=8)
ax_e.plot(mid.ts, energy.mean, "k", label="mean energy")
ax_e.fill_between(mid.ts, energy.mean - 2 * energy.standard_error,
                  energy.mean + 2 * energy.standard_error, alpha=0.3, label="± 2 s.e.")  # fmt: skip
ax_e.set(xlabel="t", title=f"energy over {paths} paths")
ax_e.legend()
for sol, name in ((mid, "stochastic midpoint"), (heun, "stochastic Heun")):
    drift = np.sort(np.maximum(sol.diagnostics.casimir_drift, 1e-18))
    ax_c.semilogy(np.arange(1, paths + 1), drift, ".", ms=3, label=name)
ax_c.set(xlabel="path (sorted)", ylabel="Casimir drift", title="Casimirs per path")
ax_c.legend()
fig.suptitle(f"Stochastic rigid body on so(3), noise 0.5, h = {h:g}, T = {T:g}")

# %%
# A 32 x 32 Heisenberg ferromagnet cooled from random spins at two temperatures: the energy
# relaxes to its thermal value, the magnetization along the field to a temperature-dependent
# value, and every spin keeps its length.

L = 32
fig_spins = Figure(figsize=(9, 3.6), layout="constrained")
ax_E, ax_M = fig_spins.subplots(1, 2)
for temperature in (0.3, 1.0):
    lattice, s0 = iso.models.spin_lattice(
        (L, L), J=-1.0, field=(0, 0, 0.2), temperature=temperature, damping=0.5, noise_seed=2
    )
    run = iso.solve(lattice, iso.StochasticIsoMP(), s0, dt=0.05, t1=20.0 if QUICK else 60.0,
                    save_every=10)  # fmt: skip
    lengths = np.linalg.norm(run.ys, axis=-1)
    print(f"T = {temperature}: max | |S_i| - 1 | = {np.abs(lengths - 1).max():.1e}")
    ax_E.plot(run.ts, lattice.hamiltonian(run.ys) / L**2, label=f"T = {temperature:g}")
    ax_M.plot(run.ts, run.ys[..., 2].mean(axis=-1), label=f"T = {temperature:g}")
ax_E.set(xlabel="t", ylabel="energy per spin", title="energy")
ax_M.set(xlabel="t", ylabel="m_z", title="magnetization along the field")
for ax in (ax_E, ax_M):
    ax.legend()
fig_spins.suptitle(f"Thermal spins (stochastic LLG), {L} x {L}, damping 0.5, h = 0.05")
