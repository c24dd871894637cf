"""
A spin lattice
==============

The classical Heisenberg model on a periodic 2-D lattice, ``w' = w x B`` with ``B`` the sum of
the four neighbours (``J = 1``), from random spins. IsoMP keeps every ``|w_i|`` and the total
spin.
"""

import os

from matplotlib.figure import Figure

import isoflow as iso

QUICK = os.environ.get("ISOFLOW_DOCS_QUICK") == "1"
L, h, T = (8 if QUICK else 16), 0.05, (5.0 if QUICK else 20.0)
prob, w0 = iso.models.spin_lattice(shape=(L, L), seed=0)
sol = iso.solve(prob, iso.IsoMP(), w0, dt=h, t1=T, save_every=5)
print(sol.message, sol.diagnostics.summary())

# %%
# The ``z`` component of the spins at the start and at the end, and the invariants.

S = sol.ys.sum(axis=1)
H = prob.hamiltonian(sol.ys)
fig = Figure(figsize=(11, 3.6), layout="constrained")
ax0, ax1, ax_s = fig.subplots(1, 3)
for ax, k, label in ((ax0, 0, "t = 0"), (ax1, -1, f"t = {T:g}")):
    im = ax.imshow(sol.ys[k, :, 2].reshape(L, L), vmin=-1, vmax=1, cmap="RdBu_r")
    ax.set(title=f"w.z on the lattice, {label}", xlabel="column", ylabel="row")
fig.colorbar(im, ax=[ax0, ax1], label="w.z")
for c, comp in enumerate("xyz"):
    ax_s.plot(sol.ts, S[:, c] - S[0, c], label=f"total spin S_{comp}(t) - S_{comp}(0)")
ax_s.plot(sol.ts, (H - H[0]) / abs(H[0]), "k--", label="(H(t) - H(0)) / |H(0)|")
ax_s.set(xlabel="t", title="invariants")
ax_s.legend(fontsize=7)
fig.suptitle(f"spin lattice {L}x{L}, J = 1, IsoMP, h = {h}, T = {T:g}")
