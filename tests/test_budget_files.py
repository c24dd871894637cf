"""Budgets, spectra and the zonal wind of forced and dissipative runs in result files, and
their panels in ``isoflow plot`` (issue 21, item 5): written per save, read back equal to the
in-memory diagnostics, the energy budget closing from the file alone, the panels drawn."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import isoflow as iso
from isoflow import io, plotting

BUDGETS = ("energy_injection", "energy_dissipation", "enstrophy_injection", "enstrophy_dissipation")
SPECTRA = ("energy_spectrum", "enstrophy_spectrum", "energy_transfer")


def _write(tmp_path: Path, model: str, **kwargs: object) -> tuple[Path, iso.Solution]:
    """A forced, damped run of ``model`` written to a result file, and the same run in memory."""
    N = 8
    F = 0.3 * iso.algebras.su(N).random(seed=6)
    build = getattr(iso.models, model)
    prob, Q0 = build(N=N, seed=7, viscosity=0.02, drag=0.1, forcing=F, **kwargs)
    path = tmp_path / f"{model}.h5"
    opts = {"dt": 0.025, "n_steps": 160, "save_every": 8, "progress": False}
    iso.solve(prob, iso.Strang(), Q0, writer=io.HDF5Writer(path), **opts)
    return path, iso.solve(prob, iso.Strang(), Q0, **opts)


@pytest.mark.parametrize(
    ("model", "kwargs"),
    [("euler_sphere", {}), ("qg_sphere", {"lamb": 20.0, "omega": 1.5})],
    ids=["euler", "qg"],
)
def test_budgets_and_spectra_are_saved_per_save_and_read_back(
    tmp_path: Path, model: str, kwargs: dict[str, float]
) -> None:
    path, sol = _write(tmp_path, model, **kwargs)
    run = io.load(path)
    n_saves, lmax = 21, 7
    for name in BUDGETS:
        got = np.asarray(run.series[f"observables/{name}"])
        assert got.shape == (n_saves,)
        assert got.tobytes() == np.asarray(sol.diagnostics.observables[name]).tobytes()
    for name in SPECTRA:
        assert np.asarray(run.series[f"observables/{name}"]).shape == (n_saves, lmax)
    # nothing the forcing changes is reported as a drift, read back or in memory
    assert not any(k.startswith("invariants/") for k in run.series)
    assert (
        run.drifts.keys()
        == sol.diagnostics.summary().keys()
        == {"casimir_drift", "max_distance", "hamiltonian_drift", "hamiltonian_relative_drift"}
    )
    transfer = np.asarray(run.series["observables/energy_transfer"])
    assert np.abs(transfer.sum(axis=1)).max() < 1e-12 * np.abs(transfer).max()
    # the energy budget closes from the file alone (trapezoid rule over 20 saves: O(dt_save^2))
    E = np.asarray(run.series["hamiltonian"])
    rate = np.asarray(run.series["observables/energy_injection"]) - np.asarray(
        run.series["observables/energy_dissipation"]
    )
    gained = float(np.trapezoid(rate, run.ts))
    assert abs(float(E[-1] - E[0]) - gained) < 1e-2 * abs(gained)
    if model == "qg_sphere":
        u = np.asarray(run.series["observables/zonal_wind"])
        assert u.shape == (n_saves, 65)
        assert u.tobytes() == np.asarray(sol.diagnostics.observables["zonal_wind"]).tobytes()


def test_plot_draws_the_budgets_spectra_and_zonal_wind(tmp_path: Path) -> None:
    path, _ = _write(tmp_path, "qg_sphere", lamb=20.0, omega=1.5)
    fig = plotting.plot_run(io.load(path))
    axes = {ax.get_title(): ax for ax in fig.axes}
    assert {"energy budget", "enstrophy budget", "energy spectrum", "zonal-mean wind"} <= set(axes)
    assert "energy transfer (sums to 0)" in axes
    params = {f"p{k}": 0.001 * k for k in range(20)}
    meta = {"method": "Strang(IsoMP)", "dt": 0.01}
    config = {"model": "euler-sphere", "params": params}
    long = type("Run", (), {"complete": True, "meta": meta, "config": config})
    title = plotting._title(long).replace("\u00a0", " ")  # wraps instead of leaving the figure
    assert title.startswith("euler-sphere (p0 = 0.0, ") and title.endswith("dt = 0.01")
    lines = title.splitlines()
    assert len(lines) > 1 and max(map(len, lines)) <= 110
    assert all(not ln.startswith("=") and not ln.endswith("=") for ln in lines)  # "k = v" kept
    # the budget panel draws injection, dissipation, their difference and dE/dt of the file
    labels = [line.get_label() for line in axes["energy budget"].get_lines()]
    assert labels == ["injection", "dissipation", "injection - dissipation", "dE/dt (saved E)"]
    # spectra at six saves (first and last included), the wind at six saves over 65 latitudes
    spectra = [ln for ln in axes["energy spectrum"].get_lines() if ln.get_label().startswith("t")]
    assert [ln.get_label() for ln in spectra][::5] == ["t = 0", "t = 4"]
    assert all(ln.get_xdata().size == 65 for ln in axes["zonal-mean wind"].get_lines()[:6])
    # rates, spectra, profiles and the enstrophy the forcing changes are not drawn as
    # invariants: the forced problem has none, the panel shows the distance to the space
    assert "invariants variation" not in axes and "distance to the space V" in axes
    plotting.save(fig, tmp_path / "q.png")
    assert (tmp_path / "q.png").stat().st_size > 0


def test_plot_of_a_run_without_diagnostics_has_no_diagnostics_row(tmp_path: Path) -> None:
    prob, W0 = iso.models.euler_sphere(N=6, seed=1)
    path = tmp_path / "ideal.h5"
    iso.solve(prob, iso.IsoMP(), W0, dt=0.05, n_steps=8, writer=io.HDF5Writer(path), progress=False)
    titles = [ax.get_title() for ax in plotting.plot_run(io.load(path)).axes]
    assert len(titles) == 4 and "energy budget" not in titles
