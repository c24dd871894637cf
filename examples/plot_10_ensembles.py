"""
Ensembles and a member that fails
=================================

An ensemble is a state with leading batch axes, solved in one call. Members are independent:
with ``throw=False`` a member whose nonlinear solve fails is frozen at its last good state and
reported by index (``Solution.failed_step``, ``Solution.failure_reasons``); the others finish.
Here the middle member is 20 times larger than the others, so ``h ||B||`` is far too large for
the fixed-point iteration at ``h = 1``.
"""

import numpy as np
from matplotlib.figure import Figure

import isoflow as iso

prob, W = iso.models.rigid_body(n=10)
ensemble = np.stack([W, 20 * W, W / 2])
h = 1.0
sol = iso.solve(prob, iso.IsoMP(), ensemble, dt=h, n_steps=200, throw=False)
print("success:", sol.success)
print("message:", sol.message)
print("failed_step:", sol.failed_step)
print("failure_reasons:", sol.failure_reasons)

# %%
# Each member's ``W[0, 1]`` entry in time; the failed member stays at its last good state.

fig = Figure(figsize=(7, 3.4), layout="constrained")
ax = fig.subplots()
for k, scale in enumerate(("W0", "20 W0", "W0 / 2")):
    status = "failed" if sol.failed_step[k] >= 0 else "finished"
    ax.plot(sol.ts, sol.ys[:, k, 0, 1] / np.abs(ensemble[k, 0, 1]),
            label=f"member {k} ({scale}): {status}")  # fmt: skip
ax.set(xlabel="t", ylabel="W[0, 1](t) / |W[0, 1](0)|",
       title=f"ensemble of 3 so(10) rigid bodies, IsoMP, h = {h}, throw=False")  # fmt: skip
ax.legend(fontsize=8)
