"""
MHD on the sphere and the heavy top: two fields, one structure
==============================================================

A magnetized fluid on the sphere carries two fields: the vorticity ``ω`` and the magnetic
potential ``θ`` (the field lines are its level lines). Zeitlin's model keeps them as a pair of
matrices ``(Θ, W)`` in ``su(N) ⋉ su(N)*``, the dual numbers ``Θ + εW``, on which the flow is
isospectral and IsoMP needs no exponential (see :doc:`/theory/semidirect`). It keeps the
integrals of ``θ^k`` and of ``ω θ^k`` to rounding while kinetic and magnetic energy trade.
The heavy top is the same structure in three dimensions.
"""

import os

import numpy as np
from matplotlib.figure import Figure

import isoflow as iso

QUICK = os.environ.get("ISOFLOW_DOCS_QUICK") == "1"
N, T = (16, 10.0) if QUICK else (32, 40.0)
h = 1.6 / N
prob, y0 = iso.models.mhd_sphere(N=N, seed=0, kinetic_energy=0.25, magnetic_energy=0.25)
sol = iso.solve(prob, iso.IsoMP(), y0, dt=h, t1=T, save_every=10)
print(sol.message)
print(f"runner: {sol.stats.runner}; {sol.stats.iterations_mean:.1f} iterations per step")

# %%
# The state at the end: the vorticity, and the current density ``j = Δθ`` with the magnetic
# field lines.

Theta, W = prob.algebra.split(sol.ys)
fig_state = iso.sphere.plot_mhd(Theta[-1], W[-1], title=f"MHD on su({N}) x| su({N})*, t = {T:g}")

# %%
# Kinetic and magnetic energy trade while their sum stays put; the two Casimir families
# (``∫θ^k``, ``k = 2..6``, and ``∫ωθ^k``, ``k = 1..5``) stay at rounding.

d = sol.diagnostics
EK, EM = iso.sphere.energy(W), iso.sphere.magnetic_energy(Theta)
fig = Figure(figsize=(11, 3.8), layout="constrained")
ax_e, ax_c, ax_s = fig.subplots(1, 3)
ax_e.plot(sol.ts, EK, label="kinetic")
ax_e.plot(sol.ts, EM, label="magnetic")
ax_e.plot(sol.ts, EK + EM, "k", label="total")
ax_e.set(xlabel="t", ylabel="energy", title="energies")
ax_e.legend()
for name in ("theta_casimirs", "cross_casimirs"):
    C = d.invariants[name]
    rel = np.max(np.abs(C - C[0]), axis=-1) / np.max(np.abs(C[0]))
    ax_c.semilogy(sol.ts, np.maximum(rel, 1e-18), label=name.replace("_", " "))
H = d.hamiltonian
ax_c.semilogy(sol.ts, np.maximum(np.abs(H / H[0] - 1), 1e-18), "k", label="energy")
ax_c.set(xlabel="t", ylabel="relative change", title="Casimirs and energy")
ax_c.legend(fontsize=8)
degrees = np.arange(1, N)
for k, when in ((0, "t = 0"), (-1, f"t = {T:g}")):
    for kind, E, style in (
        ("kinetic", iso.sphere.energy_spectrum(W[k]), "-"),
        ("magnetic", iso.sphere.magnetic_energy_spectrum(Theta[k]), "--"),
    ):
        shown = np.where(E > 1e-12 * E.max(), E, np.nan)  # the data start at l <= 10
        ax_s.loglog(degrees, shown, style, label=f"{kind}, {when}")  # fmt: skip
ax_s.set(xlabel="degree l", ylabel="E_l", title="kinetic and magnetic spectra")
ax_s.legend(fontsize=7)
fig.suptitle(f"MHD on the sphere, IsoMP, h = {h:g}, random vorticity and current (seed 0)")

# %%
# The Kovalevskaya top, ``(Γ, M)`` in ``so(3) ⋉ R^3``: the Casimirs ``|Γ|²`` and ``M·Γ`` at
# rounding, the energy and Kovalevskaya's integral bounded.

top, x0 = iso.models.heavy_top("kovalevskaya")
run = iso.solve(top, iso.IsoMP(), x0, dt=0.01, t1=100.0 if QUICK else 1000.0, save_every=20)
dt = run.diagnostics
fig_top = Figure(figsize=(8, 3.6), layout="constrained")
ax_g, ax_v = fig_top.subplots(1, 2)
ax_g.plot(run.ts, run.ys[:, 0, 2], lw=0.7, label="Γ_3 (tilt of the axis)")
ax_g.set(xlabel="t", title="Kovalevskaya top")
ax_g.legend()
for name, series in (("|Γ|², M·Γ", dt.casimirs), ("energy", dt.hamiltonian[:, None]),
                     ("K", dt.invariants["kovalevskaya"][:, None])):  # fmt: skip
    rel = np.max(np.abs(series - series[0]), axis=-1) / np.max(np.abs(series[0]))
    ax_v.semilogy(run.ts, np.maximum(rel, 1e-18), lw=0.8, label=name)
ax_v.set(xlabel="t", ylabel="relative change", title="invariants, h = 0.01")
ax_v.legend(fontsize=8)
