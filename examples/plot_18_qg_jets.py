"""
Jets on a rotating sphere: the quasi-geostrophic model
======================================================

The shallow-water quasi-geostrophic model (:func:`isoflow.models.qg_sphere`) advects the
potential vorticity ``q = Δψ - F cos²θ ψ + 2Ω cos θ``; the Lamb parameter ``F`` screens the
flow where the deformation radius ``1/(√F cos θ)`` is small, near the poles. From the same
random vorticity, turbulence on a rotating sphere organizes into zonal jets, and the larger
``F`` the weaker the wind at high latitudes (see :doc:`/theory/qg`). The Casimirs of the
potential vorticity stay at rounding.
"""

import os

import numpy as np
from matplotlib.figure import Figure

import isoflow as iso

QUICK = os.environ.get("ISOFLOW_DOCS_QUICK") == "1"
N, T = (16, 40.0) if QUICK else (32, 150.0)
omega = 5.0
runs = {}
for lamb in (0.0, 300.0):
    prob, Q0 = iso.models.qg_sphere(N=N, lamb=lamb, omega=omega, seed=1, lmin=2, lmax=12)
    runs[lamb] = iso.solve(prob, iso.IsoMP(), Q0, dt=0.02, t1=T, save_every=50)
    print(f"F = {lamb:g}: {runs[lamb].message}; Casimir drift "
          f"{runs[lamb].diagnostics.casimir_drift:.1e}")  # fmt: skip

# %%
# The zonal-mean wind (a diagnostic saved with every state) averaged over the second half of
# each run, against latitude, and over time for ``F = 300``.

fig = Figure(figsize=(10, 4), layout="constrained")
ax_p, ax_t = fig.subplots(1, 2)
for lamb, sol in runs.items():
    u = sol.diagnostics.observables["zonal_wind"]
    latitude = 90.0 - np.linspace(0.0, 180.0, u.shape[1])
    ax_p.plot(np.mean(u[len(u) // 2 :], axis=0), latitude, label=f"F = {lamb:g}")
ax_p.axvline(0.0, color="k", lw=0.5, label="no wind")
ax_p.set(xlabel="zonal-mean wind", ylabel="latitude (degrees)", title="wind profiles")
ax_p.legend()
u = runs[300.0].diagnostics.observables["zonal_wind"]
lim = float(np.max(np.abs(u)))
im = ax_t.pcolormesh(runs[300.0].ts, latitude, u.T, cmap="RdBu_r", vmin=-lim, vmax=lim,
                     shading="nearest")  # fmt: skip
fig.colorbar(im, ax=ax_t, label="zonal-mean wind")
ax_t.set(xlabel="t", ylabel="latitude (degrees)", title="jets over time, F = 300")
