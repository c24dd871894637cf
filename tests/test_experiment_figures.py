"""Every experiment is one object with its run and its figure; figures a reader can use."""

from __future__ import annotations

import pytest
from matplotlib.backends.backend_agg import FigureCanvasAgg

import isoflow as iso
from isoflow.experiments import EXPERIMENTS, ExperimentResult

#: small versions of every experiment (their own parameters, seconds in total)
SMALL = {
    "rigid-body": {"T": 5.0},
    "brockett": {"n": 4, "T": 10.0},
    "spin-chain-cost": {"Ns": (10, 20), "n_steps": 2, "repeats": 1},
    "spin-chain-energy": {"N": 10, "T": 2.0},
    "spin-chain-error": {"N": 8, "exponents": (3, 4, 5)},
    "vortices-trajectories": {},
    "vortices-invariants": {},
    "euler-sphere": {"N": 8, "T": 2.0},
    "mhd-sphere": {"quick": True, "N": 6, "T": 2.0},
    "stochastic": {
        "paths": 400,
        "fine": 6,
        "coarse": (3, 4),
        "drift_paths": 8,
        "drift_T": 0.5,
        "spins_members": 2,
        "spins_T": 4.0,
    },
    "work-precision": {"quick": True, "T": 2.0, "T_long": 10.0},
    "forced-turbulence": {"N": 16, "T": 20.0},
    "qg-jets": {"N": 12, "T": 10.0},
}


@pytest.fixture(scope="module")
def results() -> dict[str, ExperimentResult]:
    return {name: EXPERIMENTS[name](**kw, progress=False) for name, kw in SMALL.items()}


def test_every_experiment_is_covered() -> None:
    assert set(SMALL) == set(EXPERIMENTS)


@pytest.mark.parametrize("name", list(SMALL))
def test_figures_label_every_curve_and_keep_titles_clear(
    results: dict[str, ExperimentResult], name: str
) -> None:
    res = results[name]
    assert res.name == name
    fig = EXPERIMENTS[name].figure(res)
    FigureCanvasAgg(fig).draw()
    assert fig.get_suptitle() or all(ax.get_title() for ax in fig.axes)
    for ax in fig.axes:
        if ax.get_label() == "<colorbar>":
            continue
        for axis in (ax.xaxis, ax.yaxis):  # no offset text ("1e-15") colliding with the title
            assert axis.get_offset_text().get_text() == "", (name, ax.get_title())
        for line in ax.get_lines():
            assert not line.get_label().startswith("_"), (name, ax.get_title(), line)
    assert iso.plotting.plot_experiment(res).get_suptitle() == fig.get_suptitle()


def test_parameters_are_in_the_titles(results: dict[str, ExperimentResult]) -> None:
    fig = EXPERIMENTS["rigid-body"].figure(results["rigid-body"])
    assert "so(10)" in fig.get_suptitle() and "h = 0.1" in fig.get_suptitle()
    assert "T = 5" in fig.get_suptitle()
    fig = EXPERIMENTS["vortices-invariants"].figure(results["vortices-invariants"])
    assert all("h = " in ax.get_title() for ax in fig.axes)


def test_a_figure_refuses_another_experiments_result(results) -> None:
    with pytest.raises(ValueError, match="a result of 'brockett', not of 'rigid-body'"):
        EXPERIMENTS["rigid-body"].figure(results["brockett"])
    with pytest.raises(ValueError, match="no experiment called 'nothing'"):
        iso.plotting.plot_experiment(ExperimentResult("nothing", {}))


def test_the_euler_sphere_spectrum_axis_spans_the_data(
    results: dict[str, ExperimentResult],
) -> None:
    import numpy as np

    fig = EXPERIMENTS["euler-sphere"].figure(results["euler-sphere"])
    ax = next(ax for ax in fig.axes if ax.get_title() == "energy spectrum")
    drawn = np.concatenate([line.get_ydata() for line in ax.get_lines()])
    drawn = drawn[np.isfinite(drawn)]
    low, high = ax.get_ylim()
    assert low == pytest.approx(drawn.min() / 3) and high == pytest.approx(drawn.max() * 3)


def test_a_spectrum_with_nan_is_refused_whatever_its_place() -> None:
    """A NaN spectrum used to blank every curve of the axes when drawn first (the axis scale
    came from its maximum), and to draw nothing silently when drawn last."""
    import numpy as np

    good = 1.0 / np.arange(1, 11) ** 3
    bad = good.copy()
    bad[4] = np.nan
    for spectra in ({"bad": bad, "good": good}, {"good": good, "bad": bad}):
        with pytest.raises(iso.NonFiniteError, match="spectrum 'bad' must be finite"):
            iso.sphere.plot_energy_spectrum(spectra)
