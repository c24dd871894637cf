"""Every experiment in ``--quick`` form via ``isoflow reproduce all``: figures and JSON numbers."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import isoflow as iso
import isoflow.plotting
from isoflow.experiments import EXPERIMENTS


@pytest.fixture(scope="module")
def results(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("results")
    exe = shutil.which("isoflow")
    cmd = [exe] if exe else [sys.executable, "-m", "isoflow.cli"]
    res = subprocess.run(
        [*cmd, "reproduce", "all", "--quick", "--quiet", "--out", str(out)],
        capture_output=True,
        text=True,
        timeout=600,
        check=False,
    )
    assert res.returncode == 0, res.stderr
    return out


def _summary(results: Path, name: str) -> dict:
    return json.loads((results / f"{name}.json").read_text())


@pytest.mark.parametrize("name", list(EXPERIMENTS))
def test_every_experiment_writes_figures_and_a_passing_summary(results: Path, name: str) -> None:
    for suffix in (".png", ".pdf"):
        f = results / f"{name}{suffix}"
        assert f.exists() and f.stat().st_size > 1000
    assert (results / f"{name}.png").stat().st_size < 200_000
    s = _summary(results, name)
    assert s["experiment"] == name and s["isoflow_version"] == iso.__version__
    assert s["quick"] is True and s["parameters"] and s["wall_time"] > 0
    assert s["passed"], {k: v for k, v in s["checks"].items() if not v["ok"]}


def test_rigid_body_numbers(results: Path) -> None:
    s = _summary(results, "rigid-body")
    assert s["drifts"]["casimir_drift"] <= 1e-13  # eigenvalues: rounding level
    assert 1e-8 < s["drifts"]["hamiltonian_relative_drift"] < 1e-4  # O(h^2), not rounding


def test_brockett_numbers(results: Path) -> None:
    s = _summary(results, "brockett")
    assert s["drifts"]["casimir_drift"] <= 1e-13
    assert s["drifts"]["lyapunov_max_decrease"] <= 1e-13
    assert s["final_off_diagonal"] < 1e-3


def test_spin_chain_numbers(results: Path) -> None:
    err = _summary(results, "spin-chain-error")
    for method in ("isomp", "spherical"):
        assert abs(err["observed_order"][method] - 2.0) < 0.05
    errors = np.array(err["errors"]["isomp"], dtype=float)
    assert np.all(np.diff(errors) < 0)  # smaller h, smaller error
    en = _summary(results, "spin-chain-energy")
    for method in ("isomp", "spherical"):
        d = en["drifts"][method]
        assert d["casimir_drift"] <= 1e-12 and d["momentum_drift"] <= 1e-11
        assert d["hamiltonian_relative_drift"] < 1e-4
    cost = _summary(results, "spin-chain-cost")
    assert len(cost["time_per_step"]["isomp"]) == len(cost["parameters"]["Ns"])


def test_vortex_numbers(results: Path) -> None:
    tr = _summary(results, "vortices-trajectories")
    c1 = tr["runs"]["config1"]
    assert c1["circle_deviation"] < 1e-5 and c1["shape_deviation"] < 1e-5  # closed circles
    inv = _summary(results, "vortices-invariants")
    for cfg in ("config1", "config2"):
        assert inv["runs"][cfg]["drifts"]["momentum_drift"] <= 1e-13
        assert inv["runs"][cfg]["drifts"]["casimir_drift"] <= 1e-13


def test_mhd_sphere_numbers(results: Path) -> None:
    s = _summary(results, "mhd-sphere")
    assert s["drifts"]["casimir_drift"] <= 1e-12  # both families, relative
    assert s["drifts"]["angular_momentum_drift"] <= 1e-12
    assert s["energy_exchange_ratio"] >= 10 and s["energy_relative_variation"] < 1e-2
    for top in ("lagrange", "kovalevskaya"):
        assert abs(s["tops"][top]["observed_order"] - 2.0) < 0.05
        assert s["tops"][top]["drifts"]["casimir_drift"] <= 1e-11


def test_experiments_are_library_functions_with_parameters() -> None:
    res = iso.experiments.spin_chain_error(N=8, exponents=(3, 4, 5, 6))
    assert res.name == "spin-chain-error" and res.summary["parameters"]["N"] == 8
    assert abs(res.summary["observed_order"]["isomp"] - 2.0) < 0.1
    fig = iso.plotting.plot_experiment(res)
    assert len(fig.axes) == 1


def test_forced_turbulence_numbers(results: Path) -> None:
    s = _summary(results, "forced-turbulence")
    eps = s["parameters"]["eps"]
    # the realized injection is eps within its statistical error, the twin's budget closes
    assert abs(s["realized_injection_rate"] - eps) <= 3 * s["realized_injection_sd"]
    assert s["realized_injection_sd"] < 0.2 * eps  # an error bar that can fail the check
    assert s["deterministic_budget_residual"] < 1e-3
    assert s["spectrum_slope_small_scales"] < -3 < s["spectrum_slope_large_scales"]


def test_qg_jets_numbers(results: Path) -> None:
    s = _summary(results, "qg-jets")
    ratios = list(s["wind_ratio_low_over_high"].values())
    assert ratios == sorted(ratios) and ratios[-1] > 1.5
    assert all(g >= 2.0 for g in s["zonal_share_growth"].values())
    assert all(d["casimir_drift"] < 1e-11 for d in s["drifts"].values())


def test_stochastic_numbers(results: Path) -> None:
    s = _summary(results, "stochastic")
    assert abs(s["observed_order"]["strong"] - 0.5) < 0.15
    assert s["weak_order_standard_error"] < 0.15  # the weak fit is resolved
    drift = s["casimir_drift"]
    assert drift["midpoint"]["max"] <= 1e-13 and drift["heun"]["min"] > 1e-4
    assert [e["temperature"] for e in s["equilibrium"]] == [0.5, 2.0]
