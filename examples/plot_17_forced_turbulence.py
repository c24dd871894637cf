"""
Forced turbulence on the sphere: noise, hyperviscosity, drag and the energy budget
==================================================================================

Two-dimensional turbulence is driven at intermediate scales and held by dissipation at both
ends: hyperviscosity removes enstrophy at small scales, linear drag removes the energy the
inverse cascade carries to large ones. Here Euler on the sphere is forced by white noise on
the degrees ``l_f - 1 .. l_f + 1`` injecting the mean energy rate ``eps``
(:func:`isoflow.sphere.band_forcing`) and integrated by the Strang split step
(:class:`isoflow.Strang`): the exact flow of the dissipation and the noise, half a step on
each side of an IsoMP step (see :doc:`/theory/forced`). In the statistically steady state the
dissipation balances the injection.
"""

import os

import numpy as np
from matplotlib.figure import Figure

import isoflow as iso

QUICK = os.environ.get("ISOFLOW_DOCS_QUICK") == "1"
N, T = (16, 40.0) if QUICK else (32, 150.0)
lf, eps, alpha = N // 3, 0.01, 0.05
nu2 = 0.3 / (N * (N - 1.0)) ** 2  # hyperviscous rate 0.3 at the largest degree
prob, W0 = iso.models.euler_sphere(
    N=N, seed=3, rms=1e-3, hyperviscosity=(nu2, 2), drag=alpha,
    forcing_band=(lf, 1), energy_rate=eps, forcing_seed=3,
)  # fmt: skip
sol = iso.solve(prob, iso.Strang(), W0, dt=0.05, t1=T, save_every=20)
print(sol.message)
print(f"runner: {sol.stats.runner}")

# %%
# The energy rises to a plateau (drag alone would hold it at ``eps / (2 alpha)``), and the
# dissipation rate, a diagnostic saved with every state, settles at the injected ``eps``.

d = sol.diagnostics
fig = Figure(figsize=(10, 3.8), layout="constrained")
ax_e, ax_r = fig.subplots(1, 2)
ax_e.plot(sol.ts, d.hamiltonian, label="energy")
ax_e.axhline(eps / (2 * alpha), color="k", ls="--", lw=0.8, label="eps / (2 alpha)")
ax_e.set(xlabel="t", ylabel="E", title="spin-up")
ax_e.legend()
ax_r.plot(sol.ts, d.observables["energy_dissipation"], lw=0.8, label="dissipation rate")
ax_r.plot(sol.ts, d.observables["energy_injection"], "k--", lw=0.8, label="mean injection eps")
ax_r.set(xlabel="t", ylabel="rate", title="energy budget")
ax_r.legend()

# %%
# The steady-state spectrum peaks at the forcing band and falls steeply beyond it (at this
# resolution the direct-cascade range is short and hyperviscous).

fig_spectrum = Figure(figsize=(5, 3.8), layout="constrained")
ax_s = fig_spectrum.subplots()
half = len(sol.ts) // 2
spectrum = np.mean(d.observables["energy_spectrum"][half:], axis=0)
degrees = np.arange(1, N)
ax_s.loglog(degrees, np.where(spectrum > 0, spectrum, np.nan), "o-", ms=3, label="steady state")
ax_s.axvspan(lf - 1, lf + 1, color="0.85", label="forcing band")
ax_s.loglog(degrees[lf:], spectrum[lf - 1] * (degrees[lf:] / lf) ** -3.0, "k--", lw=0.7,
            label="$l^{-3}$")  # fmt: skip
ax_s.set(xlabel="degree l", ylabel="E_l", title="energy spectrum")
ax_s.legend()

# %%
# The vorticity at the end: vortices of the forcing scale, stirred at random.

iso.sphere.plot_map(sol.ys[-1], title=f"vorticity, t = {T:g}")
