"""
Euler equations on the sphere
=============================

Zeitlin's model: the vorticity as a matrix ``W`` in su(N), ``dW/dt = [B(W), W]`` with
``B(W) = Δ_N^{-1} W / ħ`` (see :doc:`/theory/euler_sphere`). From a random smooth vorticity
(degrees ``1 <= l <= 10``, rms 1), the flow transfers energy to the largest scales while
IsoMP keeps every Casimir (the spectrum of ``W``) to rounding.
"""

import os

import numpy as np
from matplotlib.figure import Figure

import isoflow as iso

QUICK = os.environ.get("ISOFLOW_DOCS_QUICK") == "1"
N, T = (32, 20.0) if QUICK else (64, 60.0)
h = 0.05
prob, W0 = iso.models.euler_sphere(N=N, seed=0)
sol = iso.solve(prob, iso.IsoMP(), W0, dt=h, t1=T, save_every=20)
print(sol.message)
print(f"runner: {sol.stats.runner}; {sol.stats.iterations_mean:.1f} iterations per step")

# %%
# The vorticity at the start and at the end (the library's map figures).

fig_start = iso.sphere.plot_map(sol.ys[0], title=f"vorticity ω, t = 0 (N = {N})")
fig_end = iso.sphere.plot_map(sol.ys[-1], title=f"vorticity ω, t = {T:g} (N = {N}, h = {h})")

# %%
# Energy spectrum ``E_l = Σ_m |ω_lm|² / (l(l+1))`` at both ends, the relative change of the
# Casimirs ``C_2 .. C_6`` and of the energy.

E = iso.sphere.energy_spectrum(sol.ys)
C = iso.sphere.casimirs(sol.ys)
H = iso.sphere.energy(sol.ys)
fig = Figure(figsize=(10, 3.8), layout="constrained")
ax_e, ax_c = fig.subplots(1, 2)
degrees = np.arange(1, E.shape[-1] + 1)
ax_e.loglog(degrees, E[0], "o-", ms=3, label="t = 0")
ax_e.loglog(degrees, E[-1], "s-", ms=3, label=f"t = {T:g}")
ax_e.set(xlabel="degree l", ylabel="E_l", title="energy spectrum")
ax_e.set_ylim(bottom=E[-1].min() / 10)  # the initial data have no energy above l = 10
ax_e.legend()
for k in range(C.shape[-1]):
    rel = np.abs(C[:, k] / C[0, k] - 1)
    ax_c.semilogy(sol.ts, np.maximum(rel, 1e-18), lw=1, label=f"C_{k + 2}")
ax_c.semilogy(sol.ts, np.maximum(np.abs(H / H[0] - 1), 1e-18), "k", label="energy H")
ax_c.set(xlabel="t", ylabel="relative change", title="Casimirs and energy")
ax_c.legend(fontsize=7, ncol=2)
fig.suptitle(f"Euler on the sphere, su({N}), IsoMP, h = {h}, T = {T:g}, random ω (seed 0)")
