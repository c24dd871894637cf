"""Figures from result files, and the experiments' figures by result.

Figures are :class:`matplotlib.figure.Figure` objects built directly (no ``pyplot``, no global
backend state), so they render headless. :func:`plot_run` draws a result file loaded with
:func:`isoflow.io.load`; :func:`plot_experiment` draws an experiment's result (each experiment
owns its figure, :meth:`isoflow.experiments.Experiment.figure`); :func:`save` writes a figure
without replacing an existing file unless told to.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

from ._figures import new_figure, plot_variation, save

if TYPE_CHECKING:
    from matplotlib.figure import Figure

    from .experiments import ExperimentResult

__all__ = ["plot_experiment", "plot_run", "save"]


def plot_experiment(res: ExperimentResult) -> Figure:
    """The paper-style figure of an experiment's result."""
    from .experiments import figure

    return figure(res)  # type: ignore[no-any-return]


def _title(run: Any) -> str:
    cfg, meta = run.config, run.meta
    params = ", ".join(f"{k} = {v}" for k, v in (cfg.get("params") or {}).items())
    title = f"{cfg.get('model', 'run')}" + (f" ({params})" if params else "")
    title += f": {meta.get('method')}, dt = {meta.get('dt'):g}"
    return title + ("" if run.complete else " (incomplete)")


def _component(run: Any, idx: tuple[int, ...]) -> str:
    """Name of one state entry: ``w_3.x`` for particles, ``W[1, 2]`` for matrices."""
    if "R^3" in str(run.meta.get("algebra", "")) and idx:
        *rest, c = idx
        return f"w_{','.join(map(str, rest))}.{'xyz'[c]}"
    return f"W[{', '.join(map(str, idx))}]"


def plot_run(run: Any) -> Figure:
    """Invariants and state components of a result file (:class:`isoflow.io.RunData`).

    Panels: Casimir variation; Hamiltonian (or Lyapunov function) variation, when the problem
    has one; the problem's invariants' variation (or the distance to the space); up to six
    state components in time. Every curve is labelled; small variations are scaled by a power
    of ten named in the axis label.
    """
    ts, s = run.ts, run.series
    energy = "hamiltonian" in s or "lyapunov" in s
    # c: Casimirs, e: energy (Hamiltonian or Lyapunov function), i: invariants, s: states
    fig = new_figure(figsize=(10, 7))
    axes = fig.subplot_mosaic("ce;is" if energy else "ci;ss", sharex=True)
    _casimir_panel(axes["c"], ts, s)
    if energy:
        _energy_panel(axes["e"], ts, s)
    _invariants_panel(axes["i"], ts, s)
    _states_panel(axes["s"], run)
    axes["i"].set_xlabel("t")
    axes["s"].set_xlabel("t")
    fig.suptitle(_title(run))
    return fig


def _casimir_panel(ax: Any, ts: Any, s: dict[str, Any]) -> None:
    C = np.real(s["casimirs"]).reshape(len(ts), -1)
    shown = min(C.shape[1], 12)
    plot_variation(ax, ts, (C - C[:1])[:, :shown], lw=0.8, ylabel="$C_j(t) - C_j(0)$",
                   labels=[f"$C_{{{j + 1}}}$" for j in range(shown)],
                   legend_columns=max(1, shown // 3))  # fmt: skip
    ax.set_title("Casimir variation" + (f" (first {shown})" if shown < C.shape[1] else ""))


def _energy_panel(ax: Any, ts: Any, s: dict[str, Any]) -> None:
    """The Hamiltonian's variation, or else the Lyapunov function."""
    if "hamiltonian" in s:
        H = np.real(s["hamiltonian"]).reshape(len(ts), -1)
        plot_variation(ax, ts, H - H[:1], lw=0.8, color="C3", ylabel="$H(t) - H(0)$",
                       labels=["Hamiltonian"] if H.shape[1] == 1 else None)  # fmt: skip
        ax.set_title("Hamiltonian variation")
    else:
        Ly = np.real(s["lyapunov"]).reshape(len(ts), -1)
        plot_variation(ax, ts, Ly, lw=0.8, color="C3", ylabel="$L(t)$",
                       labels=["Lyapunov function"] if Ly.shape[1] == 1 else None)  # fmt: skip
        ax.set_title("Lyapunov function")


def _invariants_panel(ax: Any, ts: Any, s: dict[str, Any]) -> None:
    """The variation of the problem's invariants, or else the distance to the space."""
    names = [k for k in s if k.startswith("invariants/")]
    if names:
        cols, labels = [], []
        for k in names:
            v = np.real(s[k]).reshape(len(ts), -1)
            cols.append(v - v[:1])
            label = k.split("/", 1)[1]
            labels += [label] if v.shape[1] == 1 else [f"{label}[{i}]" for i in range(v.shape[1])]
        plot_variation(ax, ts, np.concatenate(cols, axis=1), lw=0.8, ylabel="variation",
                       labels=labels)  # fmt: skip
        ax.set_title("invariants variation")
    else:
        dist = np.asarray(s["distance"]).reshape(len(ts), -1)
        plot_variation(ax, ts, dist, lw=0.8, ylabel="distance",
                       labels=["distance to V"] if dist.shape[1] == 1 else None)  # fmt: skip
        ax.set_title("distance to the space V")


def _states_panel(ax: Any, run: Any) -> None:
    """Up to six state components that move."""
    ts, ys = run.ts, np.asarray(run.ys)
    parts = [("Re ", np.real(ys)), ("Im ", np.imag(ys))] if np.iscomplexobj(ys) else [("", ys)]
    curves = [(f"{part}{_component(run, idx)}", y[(slice(None), *idx)])
              for part, y in parts for idx in np.ndindex(ys.shape[1:])]  # fmt: skip
    moving = [(label, y) for label, y in curves if np.std(y) > 0][:6]
    for label, y in moving:
        ax.plot(ts, y, lw=0.8, label=label)
    ax.set_title("state components (first six that move)")
    if moving:
        ax.legend(fontsize=7)
