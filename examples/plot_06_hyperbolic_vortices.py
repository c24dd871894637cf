"""
Point vortices on the hyperbolic plane
======================================

The paper's first configuration: three vortices in a relative equilibrium on the hyperboloid
``x^2 + y^2 - z^2 = -1``, integrated with the hyperbolic midpoint (IsoMP on
``(R^3, x_L)^3``). Shown in the Poincaré disk ``(x, y) / (1 + z)``.
"""

import os

import numpy as np
from matplotlib.figure import Figure

import isoflow as iso

QUICK = os.environ.get("ISOFLOW_DOCS_QUICK") == "1"
h, T = 0.01, (5.0 if QUICK else 10.0)
prob, w0 = iso.models.hyperbolic_vortices(config=1)
sol = iso.solve(prob, iso.IsoMP(), w0, dt=h, t1=T, save_every=2)
print(sol.message, sol.diagnostics.summary())

# %%
# Trajectories in the disk, and each vortex's distance from its hyperboloid.

x, y, z = np.moveaxis(sol.ys, -1, 0)
constraint = x**2 + y**2 - z**2 + 1
fig = Figure(figsize=(9, 4), layout="constrained")
ax_d, ax_c = fig.subplots(1, 2)
circle = np.linspace(0, 2 * np.pi, 200)
ax_d.plot(np.cos(circle), np.sin(circle), color="0.6", lw=0.8, label="boundary of the disk")
for i in range(w0.shape[0]):
    ax_d.plot(x[:, i] / (1 + z[:, i]), y[:, i] / (1 + z[:, i]), label=f"vortex {i + 1}")
ax_d.set(aspect="equal", title="Poincaré disk", xlabel="x / (1 + z)", ylabel="y / (1 + z)")
ax_d.legend(fontsize=7)
for i in range(w0.shape[0]):
    ax_c.semilogy(sol.ts, np.maximum(np.abs(constraint[:, i]), 1e-18), label=f"vortex {i + 1}")
ax_c.set(xlabel="t", ylabel="|x² + y² - z² + 1|", title="hyperboloid constraint")
ax_c.legend(fontsize=7)
fig.suptitle(f"hyperbolic vortices, paper configuration 1, hyperbolic midpoint, h = {h}, T = {T:g}")
