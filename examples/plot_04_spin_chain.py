"""
Heisenberg spin chain: IsoMP and the spherical midpoint
=======================================================

The periodic chain ``w_i' = w_i x (w_{i-1} + w_{i+1})`` on the paper's closed curve. IsoMP in
its compact R^3 form and the spherical midpoint (McLachlan–Modin–Verdier) are both symplectic
and second order; both keep each ``|w_i|`` and the total spin.
"""

import os

import numpy as np
from matplotlib.figure import Figure

import isoflow as iso

QUICK = os.environ.get("ISOFLOW_DOCS_QUICK") == "1"
N, h, T = (50 if QUICK else 100), 0.1, (20.0 if QUICK else 100.0)
prob, w0 = iso.models.heisenberg_chain(N=N)
runs = {
    "IsoMP": iso.solve(prob, iso.IsoMP(), w0, dt=h, t1=T, save_every=5),
    "spherical midpoint": iso.solve(prob, iso.SphericalMidpoint(), w0, dt=h, t1=T, save_every=5),
}
for name, sol in runs.items():
    print(f"{name:20s} {sol.stats.iterations_mean:.1f} iterations per step; {sol.message}")

# %%
# Energy error of both methods, the components of one spin, and the largest change of a
# spin's length.

fig = Figure(figsize=(10, 3.8), layout="constrained")
ax_H, ax_w, ax_n = fig.subplots(1, 3)
for (name, sol), style in zip(runs.items(), ("-", "--"), strict=True):
    H = prob.hamiltonian(sol.ys)
    ax_H.semilogy(sol.ts, np.maximum(np.abs(H / H[0] - 1), 1e-18), style, label=name)
    dn = np.abs(np.linalg.norm(sol.ys, axis=-1) - np.linalg.norm(w0, axis=-1)).max(axis=1)
    ax_n.semilogy(sol.ts, np.maximum(dn, 1e-18), style, label=name)
i = N // 4
for c, comp in enumerate("xyz"):
    ax_w.plot(runs["IsoMP"].ts, runs["IsoMP"].ys[:, i, c], label=f"w_{i}.{comp} (IsoMP)")
ax_H.set(xlabel="t", ylabel="|H(t)/H(0) - 1|", title="energy error")
ax_w.set(xlabel="t", title=f"spin {i}")
ax_n.set(xlabel="t", ylabel="max_i | |w_i(t)| - |w_i(0)| |", title="spin lengths")
for ax in (ax_H, ax_w, ax_n):
    ax.legend(fontsize=7)
fig.suptitle(f"Heisenberg spin chain, N = {N}, h = {h}, T = {T:g}")
