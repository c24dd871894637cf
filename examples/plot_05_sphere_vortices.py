"""
Point vortices on the sphere
============================

Four point vortices on the unit sphere, integrated with IsoMP on ``(R^3, x)^4``. Each vortex
stays on the sphere (``|w_i| = 1``) and the momentum ``sum_i Γ_i w_i`` is kept to rounding;
the energy error is bounded.
"""

import os

import numpy as np
from matplotlib.figure import Figure

import isoflow as iso

QUICK = os.environ.get("ISOFLOW_DOCS_QUICK") == "1"
h, T = 0.01, (5.0 if QUICK else 20.0)
theta = np.array([0.6, 1.2, 1.9, 2.4])
phi = np.array([0.0, 2.0, 4.0, 1.0])
positions = np.stack(
    [np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)], axis=-1
)
circulations = np.array([1.0, 1.0, -0.5, 0.8])
prob, w0 = iso.models.sphere_vortices(positions=positions, circulations=circulations)
sol = iso.solve(prob, iso.IsoMP(), w0, dt=h, t1=T, save_every=5)
print(sol.message, sol.diagnostics.summary())

# %%
# Trajectories projected on the ``x``–``y`` plane (north hemisphere solid, south dashed),
# and the invariants.

M = np.einsum("i,tij->tj", circulations, sol.ys)
H = prob.hamiltonian(sol.ys)
fig = Figure(figsize=(10, 3.8), layout="constrained")
ax_t, ax_m, ax_h = fig.subplots(1, 3)
for i in range(len(circulations)):
    x, y, z = sol.ys[:, i].T
    north = np.where(z >= 0, y, np.nan)
    ax_t.plot(x, north, color=f"C{i}", label=f"vortex {i + 1} (Γ = {circulations[i]:g})")
    ax_t.plot(x, np.where(z < 0, y, np.nan), "--", color=f"C{i}")
ax_t.set(xlabel="x", ylabel="y", title="trajectories (dashed: z < 0)", aspect="equal")
ax_t.legend(fontsize=7)
for c, comp in enumerate("xyz"):
    ax_m.plot(sol.ts, M[:, c] - M[0, c], label=f"M_{comp}(t) - M_{comp}(0)")
ax_m.set(xlabel="t", title="momentum Σ Γ_i w_i")
ax_m.legend(fontsize=7)
ax_h.plot(sol.ts, H / H[0] - 1, color="C3", label="H(t)/H(0) - 1")
ax_h.set(xlabel="t", title="energy, relative error")
ax_h.legend(fontsize=7)
fig.suptitle(f"4 point vortices on the sphere, IsoMP, h = {h}, T = {T:g}")
