"""
Brockett's double bracket flow
==============================

``dW/dt = [[N, W], W]`` on Hermitian 6x6 matrices with ``N = diag(1, ..., 6)``: an isospectral
flow that is not Lie–Poisson. ``Tr(W N)`` never decreases and ``W`` tends to the diagonal
matrix of its eigenvalues, sorted like the diagonal of ``N``. IsoMP keeps the eigenvalues to
rounding along the way.
"""

import os

import numpy as np
from matplotlib.figure import Figure

import isoflow as iso

QUICK = os.environ.get("ISOFLOW_DOCS_QUICK") == "1"
n, h, T = 6, 0.1, (30.0 if QUICK else 100.0)
prob, W0 = iso.models.brockett(n=n, seed=0)
sol = iso.solve(prob, iso.IsoMP(), W0, dt=h, t1=T, save_every=5)
print(sol.message)
print("eigenvalues of W0:        ", np.round(np.linalg.eigvalsh(W0), 6))
print("diagonal of W(T), real:   ", np.round(np.real(np.diag(sol.y_final)), 6))

# %%
# Left: the diagonal entries of ``W`` (real, since ``W`` is Hermitian) approach the sorted
# eigenvalues (dotted). Right: the Lyapunov function ``Tr(W N)`` and the spectrum's drift.

lam = np.linalg.eigvalsh(sol.ys)
fig = Figure(figsize=(10, 3.8), layout="constrained")
ax_d, ax_l, ax_s = fig.subplots(1, 3)
for i in range(n):
    ax_d.plot(sol.ts, np.real(sol.ys[:, i, i]), color=f"C{i}", label=f"Re W[{i},{i}]")
    ax_d.axhline(lam[0, i], color=f"C{i}", ls=":", lw=0.8)
ax_d.set(xlabel="t", ylabel="diagonal entry", title="diagonal of W (dotted: eigenvalues)")
ax_d.legend(fontsize=7, ncol=2)
ax_l.plot(sol.ts, prob.lyapunov(sol.ys), color="C3", label="Tr(W N)")
ax_l.set(xlabel="t", title="Lyapunov function")
ax_l.legend()
ax_s.semilogy(sol.ts, np.maximum(np.abs(lam - lam[0]).max(axis=1), 1e-18), label="IsoMP")
ax_s.set(xlabel="t", ylabel="max |λ_j(t) - λ_j(0)|", title="spectrum drift")
ax_s.legend()
fig.suptitle(f"Brockett flow on herm({n}), N = diag(1..{n}), IsoMP, h = {h}, T = {T:g}")
