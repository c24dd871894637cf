"""
Higher order: compositions and IsoSyRK
======================================

IsoMP is second order and symmetric, so symmetric compositions of it
(:class:`isoflow.Composition`) reach orders 4, 6 and 8 and keep every property of IsoMP;
:class:`isoflow.IsoSyRK` (isospectral symplectic Gauss–Legendre, ``s`` stages, order ``2s``)
is the other route. The orders below are measured: the slope of a least-squares fit of
``log(error)`` against ``log(h)`` (:func:`isoflow.experiments.fit_order`), against a DOP853
reference at tolerance ``1e-13``.
"""

import os

import numpy as np
from matplotlib.figure import Figure

import isoflow as iso

QUICK = os.environ.get("ISOFLOW_DOCS_QUICK") == "1"
prob, W0 = iso.models.rigid_body(n=6)
T = 1.0
ref = iso.reference_solution(prob, W0, [T])[-1]
methods = {
    "IsoMP": (iso.IsoMP(), (8, 16, 32, 64)),
    "IsoMP o suzuki-4": (iso.Composition(iso.IsoMP(), "suzuki-4"), (4, 8, 16, 32)),
    "IsoMP o yoshida-6": (iso.Composition(iso.IsoMP(), "yoshida-6"), (4, 6, 8, 12)),
    "IsoSyRK(2)": (iso.IsoSyRK(2), (4, 8, 16, 32)),
}
results = {}
for name, (method, counts) in methods.items():
    hs, errors = [], []
    for n_steps in counts:
        sol = iso.solve(prob, method, W0, dt=T / n_steps, n_steps=n_steps, diagnostics=False)
        hs.append(T / n_steps)
        errors.append(np.linalg.norm(sol.y_final - ref) / np.linalg.norm(ref))
    results[name] = (np.array(hs), np.array(errors))
    order = iso.experiments.fit_order(np.array(hs), np.array(errors))
    print(f"{name:18s} measured order {order:.2f}")

fig = Figure(figsize=(6.5, 4.2), layout="constrained")
ax = fig.subplots()
for name, (hs, errors) in results.items():
    order = iso.experiments.fit_order(hs, errors)
    ax.loglog(hs, errors, "o-", label=f"{name}: order {order:.2f}")
ax.set(xlabel="step h", ylabel="relative error at T",
       title=f"so(6) rigid body, T = {T:g}: error against the step")  # fmt: skip
ax.legend(fontsize=8)

# %%
# Work and precision
# ------------------
# ``iso.experiments.work_precision`` (also ``isoflow reproduce work-precision``) sweeps every
# method on the so(10) rigid body and the spin chain and plots the error against wall time
# and against evaluations of ``B``, with a long run comparing the Casimir and energy errors
# of the best structure-preserving method and DOP853. Its quick version runs here (the full
# one takes longer: ``T_long = 10^4``).

res = iso.experiments.work_precision.run(quick=True, T_long=20.0 if QUICK else 100.0)
fig_wp = iso.plotting.plot_experiment(res)
for name, check in res.summary.get("checks", {}).items():
    print(name, check)
