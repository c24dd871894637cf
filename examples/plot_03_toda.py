"""
The Toda lattice
================

The non-periodic Toda lattice in Flaschka's form, ``dL/dt = [B(L), L]`` with
``B = L_+ - L_-`` on symmetric tridiagonal ``L``. The flow sorts the eigenvalues onto the
diagonal. IsoMP keeps the spectrum; the tridiagonal band is not part of the space ``Sym(n)``,
so IsoMP leaves it by an ``O(h^2)`` amount that decays once the eigenvalues are sorted.
"""

import os

import numpy as np
from matplotlib.figure import Figure

import isoflow as iso

QUICK = os.environ.get("ISOFLOW_DOCS_QUICK") == "1"
n, h, T = 12, 0.1, (30.0 if QUICK else 60.0)
prob, L0 = iso.models.toda(n=n)
sol = iso.solve(prob, iso.IsoMP(), L0, dt=h, t1=T, save_every=2)
print(sol.message)

# %%
# The diagonal entries (the positions' momenta in Flaschka's variables) and the largest
# entry outside the band.

band = np.abs(np.subtract.outer(np.arange(n), np.arange(n))) > 1
off_band = np.abs(sol.ys[:, band]).max(axis=1)
lam = np.linalg.eigvalsh(sol.ys)
fig = Figure(figsize=(10, 3.8), layout="constrained")
ax_d, ax_b, ax_s = fig.subplots(1, 3)
for i in range(n):
    ax_d.plot(sol.ts, sol.ys[:, i, i], lw=1, label=f"L[{i},{i}]")
ax_d.set(xlabel="t", title="diagonal of L")
ax_d.legend(fontsize=6, ncol=2)
ax_b.semilogy(sol.ts, np.maximum(off_band, 1e-18), color="C3", label="max |L_ij|, |i-j| > 1")
ax_b.set(xlabel="t", title="distance from the band")
ax_b.legend()
ax_s.semilogy(sol.ts, np.maximum(np.abs(lam - lam[0]).max(axis=1), 1e-18), label="IsoMP")
ax_s.set(xlabel="t", ylabel="max |λ_j(t) - λ_j(0)|", title="spectrum drift")
ax_s.legend()
fig.suptitle(f"Toda lattice, n = {n}, IsoMP, h = {h}, T = {T:g}")
