"""Matplotlib figures from experiment data and from result files (no display needed).

Figures are built as :class:`matplotlib.figure.Figure` objects directly (no ``pyplot``, no
global backend state), so they render headless. :func:`plot_experiment` dispatches on the
experiment name; :func:`plot_run` draws a result file loaded with :func:`isoflow.io.load`.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.figure import Figure

from .experiments import ExperimentResult

__all__ = ["plot_experiment", "plot_run", "save"]

_DPI = 90


def save(fig: Figure, path: str | os.PathLike[str]) -> Path:
    """Write ``fig`` to ``path`` (format from the suffix: .png, .pdf, .svg)."""
    p = Path(path)
    if p.suffix.lower() not in (".png", ".pdf", ".svg"):
        raise ValueError(f"{p}: choose a .png, .pdf or .svg file name")
    fig.savefig(p, dpi=_DPI)
    return p


def _floor(x: Any) -> Any:
    """|x| with zeros lifted to the smallest positive double, for log axes."""
    return np.maximum(np.abs(np.asarray(x, dtype=float)), 1e-300)


def _rigid_body(res: ExperimentResult) -> Figure:
    d, p = res.data, res.summary["parameters"]
    fig = Figure(figsize=(7, 5.5), layout="constrained")
    ax1, ax2 = fig.subplots(2, 1, sharex=True)
    ax1.plot(d["ts"], d["casimir_variation"], lw=0.8)
    ax1.set_title("Casimir (eigenvalues) variation in time")
    ax1.set_ylabel(r"$\lambda_j(t) - \lambda_j(0)$")
    ax2.plot(d["ts"], d["hamiltonian_variation"], lw=0.8, color="C3")
    ax2.set_title("Hamiltonian variation in time")
    ax2.set_ylabel(r"$H(t) - H(0)$")
    ax2.set_xlabel("t")
    fig.suptitle(f"Generalized rigid body on so({p['n']}), IsoMP, h = {p['h']:g}")
    return fig


def _brockett(res: ExperimentResult) -> Figure:
    d, p = res.data, res.summary["parameters"]
    fig = Figure(figsize=(7, 5.5), layout="constrained")
    ax1, ax2 = fig.subplots(2, 1, sharex=True)
    ax1.plot(d["ts"], d["eigenvalue_variation"], lw=0.8)
    ax1.set_title("Casimir (eigenvalues) variation in time")
    ax1.set_ylabel(r"$\lambda_j(t) - \lambda_j(0)$")
    ax2.semilogy(d["ts"], _floor(d["off_diagonal"]), color="C3")
    ax2.set_title("W tends to a diagonal matrix")
    ax2.set_ylabel(r"$\|W - \mathrm{diag}\,W\| / \|W\|$")
    ax2.set_xlabel("t")
    fig.suptitle(f"Brockett flow on herm({p['n']}), N = diag(1..{p['n']}), IsoMP, h = {p['h']:g}")
    return fig


_LABELS = {"isomp": "isospectral minimal midpoint", "spherical": "spherical midpoint"}


def _spin_cost(res: ExperimentResult) -> Figure:
    d = res.data
    fig = Figure(figsize=(6, 4.5), layout="constrained")
    ax = fig.subplots()
    for key, style in (("isomp", "o-"), ("spherical", "s--")):
        ax.loglog(d["Ns"], d["time_per_step"][key], style, label=_LABELS[key])
    ax.set_xlabel("spin particles N")
    ax.set_ylabel("CPU time per step [s]")
    ax.set_title("Average time cost per time step")
    ax.legend()
    return fig


def _spin_energy(res: ExperimentResult) -> Figure:
    d, p = res.data, res.summary["parameters"]
    fig = Figure(figsize=(7, 5.5), layout="constrained")
    axes = fig.subplots(2, 1, sharex=True)
    for ax, key in zip(axes, ("isomp", "spherical"), strict=True):
        ax.plot(d["ts"], d["hamiltonian_variation"][key], lw=0.6)
        ax.set_title(_LABELS[key])
        ax.set_ylabel(r"$|H(kh) - H(0)|$")
    axes[-1].set_xlabel("t")
    fig.suptitle(f"Heisenberg spin chain, N = {p['N']}, h = {p['h']:g}: Hamiltonian variation")
    return fig


def _spin_error(res: ExperimentResult) -> Figure:
    d = res.data
    fig = Figure(figsize=(6, 4.5), layout="constrained")
    ax = fig.subplots()
    hs = d["hs"]
    ax.loglog(hs, d["errors"]["isomp"], "o-.", label=_LABELS["isomp"])
    ax.loglog(hs, d["errors"]["spherical"], "s--", label=_LABELS["spherical"])
    ax.loglog(hs, hs**2, "k-", lw=0.8, label=r"$h^2$")
    orders = res.summary["observed_order"]
    ax.set_title(
        f"Error diagram (observed orders {orders['isomp']:.2f}, {orders['spherical']:.2f})"
    )
    ax.set_xlabel("time step h")
    ax.set_ylabel(r"error $\max_k \|w(kh) - w_k\|$")
    ax.legend()
    return fig


def _disk(ax: Any) -> None:
    t = np.linspace(0, 2 * np.pi, 400)
    ax.plot(np.cos(t), np.sin(t), color="0.6", lw=0.8)
    ax.set_aspect("equal")


def _vortex_traj(res: ExperimentResult) -> Figure:
    runs = res.data["runs"]
    fig = Figure(figsize=(9, 4.6), layout="constrained")
    axes = fig.subplots(1, len(runs))
    for ax, r in zip(np.atleast_1d(axes), runs, strict=True):
        _disk(ax)
        ax.plot(*r["outline"].T, "r--", lw=1.0)
        for i in range(r["disk"].shape[1]):
            ax.plot(*r["disk"][:, i, :].T, lw=1.2, color=("C4", "C0", "C8")[i % 3])
            ax.plot(*r["disk"][0, i, :], "ko", ms=3)
        # zoom on the vortices, with a margin
        pts = np.concatenate([r["disk"].reshape(-1, 2), r["disk"][0]])
        lo, hi = pts.min(axis=0), pts.max(axis=0)
        c, half = (lo + hi) / 2, max(float(np.max(hi - lo)) * 0.65, 0.05)
        ax.set_xlim(c[0] - half, c[0] + half)
        ax.set_ylim(c[1] - half, c[1] + half)
        ax.set_title(f"configuration {r['config']}: h = {r['h']:g}, T = {r['T']:g}")
    fig.suptitle("Point vortex trajectories in the Poincaré disk (hyperbolic midpoint)")
    return fig


def _vortex_inv(res: ExperimentResult) -> Figure:
    runs = res.data["runs"]
    fig = Figure(figsize=(9, 5.5), layout="constrained")
    axes = fig.subplots(2, len(runs))
    for j, r in enumerate(runs):
        ax = axes[0, j]
        ax.plot(r["ts"], r["momentum_variation"], lw=0.8)
        ax.set_title(f"config {r['config']}: momentum variation")
        ax.set_ylabel(r"$M(t) - M(0)$")
        ax = axes[1, j]
        ax.plot(r["ts"], r["hamiltonian_variation"], lw=0.8, color="C3")
        ax.set_title(f"config {r['config']}: Hamiltonian variation")
        ax.set_ylabel(r"$H(t) - H(0)$")
        ax.set_xlabel("t")
    return fig


def _euler_sphere(res: ExperimentResult) -> Figure:
    from .sphere import degree_order
    from .sphere.figures import draw_map

    d, p = res.data, res.summary["parameters"]
    ts, coeffs = d["ts"], d["coefficients"]
    fig = Figure(figsize=(10.5, 6.2), layout="constrained")
    axes = fig.subplots(2, 3)
    lmax = int(np.sqrt(coeffs.shape[-1] + 1)) - 1
    # two points per wavelength, shown as cells: smaller PNG files for noisy fields
    grid: dict[str, Any] = {
        "ntheta": 2 * lmax + 2,
        "nphi": 4 * lmax + 4,
        "interpolation": "nearest",
    }
    for ax, k, what in ((axes[0, 0], 0, "initial"), (axes[0, 1], -1, "final")):
        im = draw_map(ax, coeffs[k], **grid)  # each with its own colour scale
        ax.set_title(f"{what} vorticity $\\omega$, t = {ts[k]:g}")
        fig.colorbar(im, ax=ax, shrink=0.8, label=r"$\omega$")
    ls, _ = degree_order(lmax)
    psi = -coeffs[-1] / (ls * (ls + 1.0))
    im = draw_map(axes[0, 2], psi, cmap="PuOr_r", **grid)
    axes[0, 2].set_title(f"final stream function $\\psi = \\Delta^{{-1}}\\omega$, t = {ts[-1]:g}")
    fig.colorbar(im, ax=axes[0, 2], shrink=0.8, label=r"$\psi$")
    ax = axes[1, 0]
    top = max(float(np.max(E)) for E in d["spectra"].values())
    for label, E in d["spectra"].items():
        pos = np.asarray(E) > 1e-14 * top  # below: zero up to the rounding of the transform
        ax.loglog(np.arange(1, len(E) + 1), np.where(pos, E, np.nan), label=label)
    ax.set_xlabel("degree $l$")
    ax.set_ylim(top * 1e-10, top * 3)
    ax.set_ylabel(r"$E_l = \sum_m \omega_{lm}^2 / (l(l+1))$")
    ax.set_title("energy spectrum")
    ax.legend(fontsize=8)
    ax = axes[1, 1]
    ax.plot(ts, d["large_scale_fraction"], color="C2")
    ax.set_ylim(0, 1)
    ax.set_xlabel("time $t$")
    ax.set_ylabel("energy fraction")
    ax.set_title("condensation: energy in $l \\leq 3$")
    ax = axes[1, 2]
    C = np.asarray(d["casimirs"])
    lam = np.max(np.abs(C[0]) ** (1.0 / np.arange(2, 2 + C.shape[1])))
    for j in range(C.shape[1]):
        k = j + 2
        ax.semilogy(ts, _floor(C[:, j] - C[0, j]) / (4 * np.pi * lam**k), lw=0.8,
                    label=f"$C_{{{k}}}$")  # fmt: skip
    H = np.asarray(d["energy"])
    ax.semilogy(ts, _floor(H - H[0]) / abs(H[0]), "k", lw=1.0, label="energy $H$")
    ax.set_ylim(1e-17, 1)
    ax.set_xlabel("time $t$")
    ax.set_ylabel("relative variation")
    ax.set_title("Casimirs and energy")
    ax.legend(fontsize=7, ncol=2)
    rot = f", $\\Omega$ = {p['omega']:g}" if p.get("omega") else ""
    fig.suptitle(
        f"Euler equations on the sphere (Zeitlin, su({p['N']})){rot}: IsoMP, h = {p['h']:.3g}, "
        f"T = {p['T']:g}, random initial vorticity (seed {p['seed']})"
    )
    return fig


_PLOTS: dict[str, Callable[[ExperimentResult], Figure]] = {
    "rigid-body": _rigid_body,
    "brockett": _brockett,
    "spin-chain-cost": _spin_cost,
    "spin-chain-energy": _spin_energy,
    "spin-chain-error": _spin_error,
    "vortices-trajectories": _vortex_traj,
    "vortices-invariants": _vortex_inv,
    "euler-sphere": _euler_sphere,
}


def plot_experiment(res: ExperimentResult) -> Figure:
    """The paper-style figure of an experiment's result."""
    try:
        fn = _PLOTS[res.name]
    except KeyError:
        raise ValueError(f"no figure for experiment {res.name!r}") from None
    return fn(res)


def plot_run(run: Any) -> Figure:
    """Invariants and state components of a result file (:class:`isoflow.io.RunData`).

    Panels: Casimir variation (relative to the largest first-state Casimir), Hamiltonian (or
    Lyapunov function) variation, the problem's invariants' variation, and up to six state
    components in time.
    """
    ts, s = run.ts, run.series
    fig = Figure(figsize=(9, 6.5), layout="constrained")
    axes = fig.subplots(2, 2, sharex=True).ravel()
    C = np.real(s["casimirs"]).reshape(len(ts), -1)
    axes[0].plot(ts, C - C[:1], lw=0.8)
    axes[0].set_title("Casimir variation")
    if "hamiltonian" in s:
        H = np.real(s["hamiltonian"]).reshape(len(ts), -1)
        axes[1].plot(ts, H - H[:1], lw=0.8, color="C3")
        axes[1].set_title("Hamiltonian variation")
    elif "lyapunov" in s:
        Ly = np.real(s["lyapunov"]).reshape(len(ts), -1)
        axes[1].plot(ts, Ly, lw=0.8, color="C3")
        axes[1].set_title("Lyapunov function")
    else:
        axes[1].set_title("(no Hamiltonian)")
    names = [k for k in s if k.startswith("invariants/")]
    for k in names:
        v = np.real(s[k]).reshape(len(ts), -1)
        axes[2].plot(ts, v - v[:1], lw=0.8, label=k.split("/", 1)[1])
    axes[2].set_title("invariants variation" if names else "distance to V")
    if names:
        axes[2].legend(fontsize=8)
    else:
        axes[2].plot(ts, np.asarray(s["distance"]).reshape(len(ts), -1), lw=0.8)
    Y = np.real(run.ys).reshape(len(ts), -1)
    pick: Any = np.flatnonzero(np.std(Y, axis=0) > 0)[:6] if Y.size else []
    for j in pick:
        axes[3].plot(ts, Y[:, j], lw=0.8, label=f"y[{j}]")
    axes[3].set_title("state components (first six that move)")
    if len(pick):
        axes[3].legend(fontsize=8)
    for ax in axes[2:]:
        ax.set_xlabel("t")
    cfg = run.config
    title = f"{cfg.get('model', 'run')} {cfg.get('params', '')}, {run.meta.get('method')}"
    title += f", dt = {run.meta.get('dt'):g}" + ("" if run.complete else " (incomplete)")
    fig.suptitle(title)
    return fig
