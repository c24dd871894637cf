"""Figures from result files, and the experiments' figures by result.

Figures are :class:`matplotlib.figure.Figure` objects built directly (no ``pyplot``, no global
backend state), so they render headless. :func:`plot_run` draws a result file loaded with
:func:`isoflow.io.load`; :func:`plot_experiment` draws an experiment's result (each experiment
owns its figure, :meth:`isoflow.experiments.Experiment.figure`); :func:`save` writes a figure
without replacing an existing file unless told to.
"""

from __future__ import annotations

import textwrap
from typing import TYPE_CHECKING, Any

import numpy as np

from ._figures import new_figure, plot_variation, save

if TYPE_CHECKING:
    from matplotlib.figure import Figure

    from .experiments import ExperimentResult

__all__ = ["plot_experiment", "plot_run", "save"]


def plot_experiment(res: ExperimentResult) -> Figure:
    """The paper-style figure of an experiment's result.

    Parameters
    ----------
    res : ExperimentResult
        What :meth:`Experiment.run <isoflow.experiments.Experiment.run>` returned; its
        ``name`` selects the figure.

    Returns
    -------
    matplotlib.figure.Figure
    """
    from .experiments import figure

    return figure(res)  # type: ignore[no-any-return]


def _title(run: Any, member: str = "") -> str:
    cfg, meta = run.config, run.meta
    params = ", ".join(f"{k} = {v}" for k, v in (cfg.get("params") or {}).items())
    title = f"{cfg.get('model', 'run')}" + (f" ({params})" if params else "")
    title += f": {meta.get('method')}, dt = {meta.get('dt'):g}" + member
    info = getattr(run, "run_info", None)
    info = info if isinstance(info, dict) else {}
    if info.get("status") == 1:
        title += " (failed: see its message)"
    elif not run.complete:
        title += " (incomplete)"
    # long parameter lists wrap between parameters (no-break spaces keep "k = v" together),
    # instead of running off both edges of the figure
    return textwrap.fill(title.replace(" = ", "\u00a0=\u00a0"), width=110)


def _component(run: Any, idx: tuple[int, ...]) -> str:
    """Name of one state entry: ``w_3.x`` for particles, ``W[1, 2]`` for matrices, ``M.x`` and
    ``Theta[1, 2]`` for the fields of a pair (their names as the file records them)."""
    fields = run.meta.get("fields")
    if isinstance(fields, list) and len(fields) == 2 and idx:
        name, inner = str(fields[idx[0]]), idx[1:]
        if "R^3" in str(run.meta.get("algebra", "")) and len(inner) == 1:
            return f"{name}.{'xyz'[inner[0]]}"
        return f"{name}[{', '.join(map(str, inner))}]"
    if "R^3" in str(run.meta.get("algebra", "")) and idx:
        *rest, c = idx
        return f"w_{','.join(map(str, rest))}.{'xyz'[c]}"
    return f"W[{', '.join(map(str, idx))}]"


def plot_run(run: Any, member: int | tuple[int, ...] | None = None) -> Figure:
    """Invariants and state components of a result file (:class:`isoflow.io.RunData`).

    Panels: Casimir variation; Hamiltonian (or Lyapunov function) variation, when the problem
    has one; the problem's invariants' variation (or the distance to the space); up to six
    state components in time. Every curve is labelled; small variations are scaled by a power
    of ten named in the axis label.

    Parameters
    ----------
    run : isoflow.io.RunData
        The file's contents, :func:`isoflow.io.load`.
    member : int or tuple of int, optional
        For an ensemble: the member drawn (its index, flat or one per ensemble axis; default
        0), named in the title. A figure shows one member; draw others by calling again.

    Raises
    ------
    ParameterError
        ``member`` for a single system, or out of the ensemble's range.

    A run of a forced or dissipative sphere model adds a row of diagnostics (each panel when
    its series is in the file): the energy budget (injection and dissipation rates against
    :math:`dE/dt` from the saved energy), the enstrophy budget's rates, the energy spectrum
    at up to six saves, the energy transfer spectrum (the bracket's; first and last save)
    and, for the quasi-geostrophic model, the zonal-mean wind against latitude over time.
    """
    run, which = _one_member(run, member)
    ts, s = run.ts, run.series
    energy = "hamiltonian" in s or "lyapunov" in s
    extra = _diagnostic_panels(s)
    # c: Casimirs, e: energy (Hamiltonian or Lyapunov function), i: invariants, s: states;
    # the diagnostics row: b, z energy and enstrophy budgets, p spectra, t transfer, w wind
    top = [["c", "e"], ["i", "s"]] if energy else [["c", "i"], ["s", "s"]]
    rows = [[k for k in row for _ in range(3)] for row in top]  # six columns
    for group in extra:
        rows.append([k for k in group for _ in range(6 // len(group))])
    fig = new_figure(figsize=(10, 7 + 3.5 * len(extra)))
    axes = fig.subplot_mosaic(rows)  # type: ignore[arg-type]
    for key in ("e", "i", "s", "b", "z"):
        if key in axes:
            axes[key].sharex(axes["c"])
    _casimir_panel(axes["c"], ts, s)
    if energy:
        _energy_panel(axes["e"], ts, s)
    _invariants_panel(axes["i"], ts, s)
    _states_panel(axes["s"], run)
    axes["i"].set_xlabel("t")
    axes["s"].set_xlabel("t")
    drawers = {"b": _budget_panel, "z": _enstrophy_panel, "p": _spectrum_panel,
               "t": _transfer_panel, "w": _wind_panel}  # fmt: skip
    for group in extra:
        for key in group:
            drawers[key](axes[key], ts, s)
    fig.suptitle(_title(run, which))
    return fig


def _one_member(run: Any, member: int | tuple[int, ...] | None) -> tuple[Any, str]:
    """``(run, words)``: an ensemble's run cut to one member (its states and series, with
    ``words`` naming it for the title), a single system's as it is."""
    import dataclasses

    from ._errors import ParameterError

    batch = run.batch_shape
    if not batch:
        if member is not None:
            raise ParameterError(f"member={member!r}: this run is one system, not an ensemble")
        return run, ""
    size = int(np.prod(batch))
    try:
        if member is None:
            index: tuple[int, ...] = (0,) * len(batch)
        elif isinstance(member, (int, np.integer)) and not isinstance(member, bool):
            if not 0 <= int(member) < size:
                raise ValueError
            index = tuple(int(i) for i in np.unravel_index(int(member), batch))
        else:
            index = tuple(int(i) for i in member)  # type: ignore[union-attr]
            if len(index) != len(batch) or not all(
                0 <= i < n for i, n in zip(index, batch, strict=True)
            ):
                raise ValueError
    except (TypeError, ValueError):
        raise ParameterError(
            f"member={member!r} is not a member of this ensemble of shape {batch}: give an "
            f"index below {size} or a tuple of {len(batch)} indices"
        ) from None
    cut: tuple[Any, ...] = (slice(None), *index)
    one = dataclasses.replace(
        run, ys=np.asarray(run.ys)[cut],
        series={k: np.asarray(v)[cut] for k, v in run.series.items()},
        meta={**run.meta, "state_shape": list(run.meta["core_shape"])},
    )  # fmt: skip
    label = index[0] if len(index) == 1 else index
    return one, f", member {label} of {size}"


def _diagnostic_panels(s: dict[str, Any]) -> list[list[str]]:
    """The keys of the diagnostics panels the series ``s`` fill, by row: the budgets, then
    the spectra and the wind (no empty row)."""
    has = {k.split("/", 1)[1] for k in s if k.startswith("observables/")}
    budgets = [key for key, names in (("b", {"energy_injection", "energy_dissipation"}),
                                      ("z", {"enstrophy_injection", "enstrophy_dissipation"}))
               if has & names]  # fmt: skip
    profiles = [key for key, name in (("p", "energy_spectrum"), ("t", "energy_transfer"),
                                      ("w", "zonal_wind"))
                if name in has]  # fmt: skip
    return [row for row in (budgets, profiles) if row]


def _budget_panel(ax: Any, ts: Any, s: dict[str, Any]) -> None:
    """Energy injection and dissipation rates and :math:`dE/dt` of the saved energy: the
    budget closes when ``injection - dissipation`` follows ``dE/dt``."""
    _rates(ax, ts, s, "energy")
    if "hamiltonian" in s and len(ts) >= 3:
        E = np.real(s["hamiltonian"]).reshape(-1)
        ax.plot(ts, np.gradient(E, ts), "k:", lw=1.2, label="dE/dt (saved E)")
    ax.set_title("energy budget")
    ax.legend(fontsize=7)


def _enstrophy_panel(ax: Any, ts: Any, s: dict[str, Any]) -> None:
    """Enstrophy injection and dissipation rates (of the relative vorticity)."""
    _rates(ax, ts, s, "enstrophy")
    ax.set_title("enstrophy budget")
    ax.legend(fontsize=7)


def _rates(ax: Any, ts: Any, s: dict[str, Any], quantity: str) -> None:
    """The injection, dissipation and net rates of ``quantity`` (``energy``, ``enstrophy``)."""
    zero = np.zeros(len(ts))
    inj = np.real(s.get(f"observables/{quantity}_injection", zero)).reshape(-1)
    dis = np.real(s.get(f"observables/{quantity}_dissipation", zero)).reshape(-1)
    ax.plot(ts, inj, lw=0.9, label="injection")
    ax.plot(ts, dis, lw=0.9, label="dissipation")
    ax.plot(ts, inj - dis, lw=0.9, color="k", label="injection - dissipation")
    ax.set_xlabel("t")
    ax.set_ylabel(f"{quantity} rate")


def _save_indices(n: int, most: int = 6) -> list[int]:
    """Up to ``most`` save indices spread from the first to the last of ``n``."""
    return sorted({round(float(i)) for i in np.linspace(0, n - 1, min(n, most))})


def _spectrum_panel(ax: Any, ts: Any, s: dict[str, Any]) -> None:
    """The saved energy spectrum at up to six saves (log-log)."""
    from .sphere.figures import draw_energy_spectrum

    E = np.real(s["observables/energy_spectrum"])
    draw_energy_spectrum(ax, {f"t = {ts[i]:.3g}": E[i] for i in _save_indices(len(ts))})
    ax.set_title("energy spectrum")


def _transfer_panel(ax: Any, ts: Any, s: dict[str, Any]) -> None:
    """The bracket's energy transfer per degree at the first and the last save."""
    T = np.real(s["observables/energy_transfer"])
    ls = np.arange(1, T.shape[1] + 1)
    for i in sorted({0, len(ts) - 1}):
        ax.plot(ls, T[i], lw=0.9, marker=".", label=f"t = {ts[i]:.3g}")
    ax.axhline(0.0, color="k", lw=0.5)
    ax.set_xscale("log")
    ax.set_xlabel("degree $l$")
    ax.set_ylabel("$T_l$")
    ax.set_title("energy transfer (sums to 0)")
    ax.legend(fontsize=7)


def _wind_panel(ax: Any, ts: Any, s: dict[str, Any]) -> None:
    """The zonal-mean eastward wind against latitude, one curve per save (up to six)."""
    u = np.real(s["observables/zonal_wind"])
    lat = 90.0 - np.linspace(0.0, 180.0, u.shape[1])  # saved pole to pole in colatitude
    for i in _save_indices(len(ts)):
        ax.plot(u[i], lat, lw=0.9, label=f"t = {ts[i]:.3g}")
    ax.axvline(0.0, color="k", lw=0.5)
    ax.set_xlabel("zonal-mean wind $\\bar u$")
    ax.set_ylabel("latitude (degrees)")
    ax.set_title("zonal-mean wind")
    ax.legend(fontsize=7)


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
