"""Zeitlin's MHD on the sphere: the kernel, the continuum limit of the equations, Alfvénic steady
states, the Euler limit, conservation and order under IsoMP, compiled against NumPy, the
diagnostics and initial data, errors, result files (command line, kill and resume).

Expected values come from independent computations: the continuum MHD tendencies evaluated on
a grid (ducc0 gradients), exact coefficient formulas of the energies, DOP853.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import ducc0
import numpy as np
import pytest

import isoflow as iso
from helpers import (
    assert_same_run,
    compiled_and_numpy,
    disk_before_sampled_writes,
    loglog_slope,
)
from isoflow import io, sphere
from isoflow.sphere._grid import _to_alm


def bracket_coefficients(a: np.ndarray, b: np.ndarray, lmax: int) -> np.ndarray:
    r"""Coefficients (degree <= 2 lmax) of the continuum bracket :math:`\{a, b\} =
    \frac1{\sin\vartheta}(a_\vartheta b_\varphi - a_\varphi b_\vartheta)` of two fields given by
    coefficients up to ``lmax``, from ducc0's gradients on a grid fine enough to be exact."""
    nt = 2 * lmax + 2
    (at, ap), (bt, bp) = (
        ducc0.sht.synthesis_2d_deriv1(
            alm=_to_alm(c[None], lmax), lmax=lmax, geometry="GL", ntheta=nt, nphi=2 * nt
        )
        for c in (a, b)
    )
    return sphere.analyze(at * bp - ap * bt, 2 * lmax, geometry="GL")


def test_kernel_B_is_the_stream_matrix_and_the_current_over_hbar() -> None:
    """B = (P / hbar + i Omega J_3, Delta_N Theta / hbar) at a stage of u(N) pairs (the traces
    of a stage drop out), against the Poisson solve and the Laplacian of ``iso.sphere``."""
    N, omega = 9, 0.6
    prob, _ = iso.models.mhd_sphere(N=N, omega=omega, seed=4)
    X = prob.algebra.stage_algebra.random(2)
    B = prob.evaluate_B(X)
    h = sphere.hbar(N)
    th_x, q_x = prob.algebra.split(X)
    J3 = np.diag(np.arange(N) - 0.5 * (N - 1))
    np.testing.assert_allclose(B[0], sphere.solve_poisson(q_x) / h + 1j * omega * J3, atol=1e-13)
    np.testing.assert_allclose(B[1], sphere.laplacian(th_x) / h, atol=1e-12)
    assert prob.parameters["N"] == N and prob.parameters["omega"] == omega


@pytest.mark.parametrize("omega", [0.0, 0.7])
def test_vector_field_converges_to_continuum_mhd(omega: float) -> None:
    r"""theta' = {theta, psi} and omega' = {omega + f, psi} + {theta, j} (the quantized
    tendencies in coefficients against the continuum ones): second order in 1/N. A sign or a
    scale error in the coupling [J, Theta] would not converge."""
    L0 = 4
    rng = np.random.default_rng(3)
    cw, ct = rng.standard_normal((2, sphere.coefficient_count(L0)))
    ls, _ = sphere.degree_order(L0)
    psi, j = -cw / (ls * (ls + 1.0)), -ls * (ls + 1.0) * ct
    q = cw.copy()
    q[sphere.lm_index(1, 0)] += 2 * omega * np.sqrt(4 * np.pi / 3)  # f = 2 Omega z
    ref_w = bracket_coefficients(q, psi, L0) + bracket_coefficients(ct, j, L0)
    ref_t = bracket_coefficients(ct, psi, L0)
    k = ref_w.size
    errs = []
    Ns = (12, 24, 48)
    for N in Ns:
        W0, T0 = sphere.from_coefficients(cw, N), sphere.from_coefficients(ct, N)
        prob, y0 = iso.models.mhd_sphere(N=N, omega=omega, W0=W0, Theta0=T0)
        ft, fw = prob.algebra.split(prob.vector_field(y0))
        ct_dot, cw_dot = sphere.to_coefficients(ft), sphere.to_coefficients(fw)
        top = np.max(np.abs(cw_dot))
        assert np.max(np.abs(cw_dot[k:]), initial=0.0) <= 1e-12 * top  # none above degree 2 L0
        errs.append(
            max(np.max(np.abs(cw_dot[:k] - ref_w)) / np.max(np.abs(ref_w)),
                np.max(np.abs(ct_dot[:k] - ref_t)) / np.max(np.abs(ref_t)))
        )  # fmt: skip
    order = -np.polyfit(np.log(Ns), np.log(errs), 1)[0]
    assert 1.9 < order < 2.1, errs
    assert errs[-1] < 2e-2  # measured 1.0e-2


@pytest.mark.parametrize("sign", [1.0, -1.0])
def test_alfvenic_states_are_steady(sign: float) -> None:
    r"""theta = +-psi (u = +-b) is steady for ideal MHD: the quantized Theta = +-P gives
    [P, Theta] = 0 and [P, W] + [J, Theta] = [P, W] + [W, P] = 0 (J = Delta_N Theta = +-W)."""
    N = 10
    W = sphere.random_vorticity(N, seed=5)
    prob, y0 = iso.models.mhd_sphere(N=N, W0=W, Theta0=sign * sphere.solve_poisson(W))
    f = prob.vector_field(y0)
    assert np.max(np.abs(f)) <= 1e-12 * np.max(np.abs(prob.evaluate_B(y0))) * np.max(np.abs(y0))
    off, _ = iso.models.mhd_sphere(N=N, W0=W, Theta0=0.5 * sign * sphere.solve_poisson(W))
    assert np.max(np.abs(off.vector_field(off.algebra.validate(off.algebra.pair(
        0.5 * sign * sphere.solve_poisson(W), W))))) > 1e-3  # fmt: skip


def test_zero_magnetic_potential_is_the_euler_model() -> None:
    """Theta = 0 stays exactly zero and the vorticity follows the Euler model to rounding (the
    NumPy path and the compiled path)."""
    N = 12
    pe, q0 = iso.models.euler_sphere(N=N, omega=0.4, seed=1)
    F = iso.models.coriolis_matrix(N, 0.4)
    pm, m0 = iso.models.mhd_sphere(N=N, omega=0.4, W0=q0 - F)
    assert np.max(np.abs(m0[1] - q0)) <= 1e-15 and np.all(m0[0] == 0)
    for kernel in (False, True):
        a = pe if kernel else dataclasses.replace(pe, kernel=None)
        b = pm if kernel else dataclasses.replace(pm, kernel=None)
        se = iso.solve(a, iso.IsoMP(), m0[1], dt=0.05, n_steps=60, save_every=20)
        sm = iso.solve(b, iso.IsoMP(), m0, dt=0.05, n_steps=60, save_every=20)
        assert sm.stats.runner.startswith("compiled") == kernel
        assert np.all(sm.ys[:, 0] == 0)
        assert np.max(np.abs(sm.ys[:, 1] - se.ys)) <= 1e-14 * np.max(np.abs(se.ys))
        assert float(np.max(np.abs(se.ys[-1] - se.ys[0]))) > 0.1  # the flow moved


@pytest.mark.parametrize(
    ("N", "omega", "h", "n_steps"), [(16, 0.0, 0.1, 5000), (24, 1.0, 0.05, 3000)]
)
def test_both_casimir_families_at_rounding_and_the_energy_bounded(
    N: int, omega: float, h: float, n_steps: int
) -> None:
    """Thousands of compiled steps: the algebra's Casimirs (spectrum of Theta, the cross family)
    and the normalized integrals of theta^k and (omega + f) theta^k within one rounding per
    step of their scale; the energy bounded (1%) while kinetic and magnetic energy trade ten
    times more; the angular momentum to rounding."""
    prob, y0 = iso.models.mhd_sphere(N=N, omega=omega, seed=2)
    sol = iso.solve(prob, iso.IsoMP(), y0, dt=h, n_steps=n_steps, save_every=n_steps // 50)
    assert sol.stats.runner.startswith("compiled, dual pairs")
    d = sol.diagnostics
    budget = n_steps * np.finfo(float).eps
    assert float(d.casimir_drift) <= budget
    for name in ("theta_casimirs", "cross_casimirs"):
        C = d.invariants[name]
        assert np.max(np.abs(C - C[0])) <= budget * np.max(np.abs(C[0])), name
    key = "angular_momentum" if omega == 0 else "angular_momentum_z"
    assert np.max(d.invariant_drift[key]) <= budget
    theta, q = prob.algebra.split(sol.ys)
    F = iso.models.coriolis_matrix(N, omega)
    EK, EM = sphere.energy(q - F), sphere.magnetic_energy(theta)
    H = d.hamiltonian
    np.testing.assert_allclose(EK + EM, H, rtol=1e-13)
    assert np.max(np.abs(H - H[0])) / H[0] <= 1e-2
    assert min(np.ptp(EK), np.ptp(EM)) >= 10 * np.ptp(H)  # exchange, not drift


def test_isomp_is_second_order_against_dop853() -> None:
    prob, y0 = iso.models.mhd_sphere(N=5, seed=3, lmax=3)
    T = 1.0
    ref = iso.reference_solution(prob, y0, [T])[0]
    hs = np.array([0.1, 0.05, 0.025])
    errs = []
    for h in hs:
        sol = iso.solve(prob, iso.IsoMP(), y0, dt=float(h), t1=T, save_every=10**6)
        errs.append(float(np.max(np.abs(sol.ys[-1] - ref))))
    assert min(errs) > 1e-9
    assert loglog_slope(hs, np.array(errs)) == pytest.approx(2.0, abs=0.05)


@pytest.mark.parametrize("N", [6, 20])
def test_compiled_equals_numpy(N: int) -> None:
    prob, y0 = iso.models.mhd_sphere(N=N, seed=1, lmax=min(5, N - 1))
    _, y1 = iso.models.mhd_sphere(N=N, seed=2, lmax=min(5, N - 1), magnetic_energy=0.1)
    a, n = compiled_and_numpy(prob, iso.IsoMP(), np.stack([y0, y1]), 0.5 / N, 20, 5, chunks=(7, 13))
    assert_same_run(a, n)


def test_initial_data_energies_and_spectra() -> None:
    N = 16
    prob, y0 = iso.models.mhd_sphere(N=N, seed=7, lmin=2, lmax=6, slope=-1.0,
                                     kinetic_energy=0.3, magnetic_energy=0.8)  # fmt: skip
    theta, w = prob.algebra.split(y0)
    ct, cw = sphere.to_coefficients(theta), sphere.to_coefficients(w)
    ls, _ = sphere.degree_order(N - 1)
    assert 0.5 * np.sum(cw**2 / (ls * (ls + 1.0))) == pytest.approx(0.3, rel=1e-12)
    assert 0.5 * np.sum(ls * (ls + 1.0) * ct**2) == pytest.approx(0.8, rel=1e-12)
    assert float(sphere.magnetic_energy(theta)) == pytest.approx(0.8, rel=1e-12)
    EM = sphere.magnetic_energy_spectrum(theta)
    assert EM.sum() == pytest.approx(1.6, rel=1e-12) and np.all(EM[:1] < 1e-20)  # l >= 2
    assert np.all(EM[6:] < 1e-20)  # l <= 6
    np.testing.assert_allclose(EM, sphere.energy_spectrum(sphere.current(theta)), rtol=1e-10,
                               atol=1e-20)  # fmt: skip
    assert np.allclose(sphere.magnetic_energy_spectrum(ct), EM, rtol=1e-12)
    H1 = sphere.cross_casimirs(theta, w, kmax=3)[0]
    assert H1 == pytest.approx(np.sum(cw * ct), rel=1e-10)  # int omega theta, orthonormal Y_lm
    _, again = iso.models.mhd_sphere(N=N, seed=7, lmin=2, lmax=6, slope=-1.0,
                                     kinetic_energy=0.3, magnetic_energy=0.8)  # fmt: skip
    assert again.tobytes() == y0.tobytes()
    _, zero = iso.models.mhd_sphere(N=N, magnetic_energy=0.0)
    assert np.all(zero[0] == 0)


def test_bad_input_gives_one_line_typed_errors() -> None:
    su4 = iso.algebras.su(4)
    cases = [
        ({"N": 4, "W0": su4.random(1), "Theta0": iso.algebras.su(5).random(1)}, iso.ShapeError,
         "must have one shape: Theta has (5, 5), W has (4, 4)"),
        ({"N": 4, "W0": iso.algebras.su(3).random(1)}, iso.ShapeError,
         "have shape (*batch, 4, 4), got (3, 3)"),
        ({"N": 4, "Theta0": su4.random(1) + np.eye(4)}, iso.NotInSpaceError,
         "the initial pair (Theta0, W0) is not in su(4) x| su(4)*: its field Theta (index 0)"),
        ({"N": 4, "magnetic_energy": -1.0}, iso.ParameterError,
         "magnetic_energy must be finite and >= 0"),
        ({"N": 4, "lmax": 4}, iso.ParameterError, "lmax must be <= N - 1 = 3"),
        ({"N": 1}, iso.ParameterError, "N must be >= 2"),
        ({"N": 4, "seed": 1.5}, iso.ParameterError, "seed must be an integer"),
    ]  # fmt: skip
    for kw, kind, text in cases:
        with pytest.raises(kind) as err:
            iso.models.mhd_sphere(**kw)
        assert text in str(err.value) and "\n" not in str(err.value), (kw, str(err.value))


# ---- result files: the command line, and a kill at any write resumed bit for bit ---------------


def test_run_info_plot_through_the_command_line(tmp_path: Path, capsys) -> None:
    from isoflow.cli import main

    out = tmp_path / "mhd.h5"
    args = ["run", "mhd-sphere", "--N", "6", "--dt", "0.05", "--n-steps", "40",
            "--save-every", "10", "--out", str(out), "--quiet"]  # fmt: skip
    assert main(args) == 0
    run = io.load(out)
    assert run.ys.shape == (5, 2, 6, 6) and run.complete
    assert run.drifts["casimir_drift"] < 1e-13
    assert set(run.series) >= {"casimirs", "invariants/theta_casimirs", "invariants/cross_casimirs"}
    capsys.readouterr()
    assert main(["info", str(out)]) == 0
    shown = capsys.readouterr().out
    assert "mhd-sphere" in shown and "su(6) x| su(6)*" in shown and "(2, 6, 6)" in shown
    png = tmp_path / "mhd.png"
    assert main(["plot", str(out), "--out", str(png)]) == 0
    assert png.read_bytes()[:4] == b"\x89PNG"
    fig = sphere.plot_mhd(*iso.algebras.semidirect(iso.algebras.su(6)).split(run.ys[-1]))
    assert len(fig.axes) == 4 and "field lines" in fig.axes[1].get_title()


CFG = {"model": "mhd-sphere", "params": {"N": 5, "lmax": 3}, "dt": 0.05, "n_steps": 600,
       "save_every": 3}  # fmt: skip


def _solve(path: Path) -> iso.Solution:
    cfg = iso.registry.normalize_config(CFG)
    problem, y0, method, kw = iso.registry.build(cfg)
    writer = io.HDF5Writer(path, cfg, chunk_rows=16, flush_seconds=0.01)
    return iso.solve(problem, method, y0, **kw, progress=False, writer=writer)


def test_a_kill_at_any_write_of_an_mhd_run_resumes_bit_for_bit(tmp_path: Path) -> None:
    """The file as it was just before a random write (an in-process kill there) resumes to the
    uninterrupted run: both fields, every saved state, bit for bit."""
    _solve(tmp_path / "ref.h5")
    ref = io.load(tmp_path / "ref.h5")
    final = tmp_path / "run.h5"
    with disk_before_sampled_writes(final, 6, np.random.default_rng(5)) as seen:
        _solve(final)
    assert seen["writes"] >= 20 and len(seen["copies"]) == 6, seen["writes"]
    copies = []
    for i, data in enumerate(seen["copies"]):
        copies.append(tmp_path / f"kill{i}.h5")
        copies[-1].write_bytes(data)
    for path in copies:
        part = io.load(path)
        assert part.ys.tobytes() == ref.ys[: len(part.ys)].tobytes()
        io.resume(path, progress=False)
        got = io.load(path)
        assert got.complete and got.ys.tobytes() == ref.ys.tobytes()
        assert got.drifts == ref.drifts


def test_a_restart_continues_the_stored_state_not_a_reprojection() -> None:
    """su(N) states after a step are not fixed points of the projection in floating point (its
    trace removal moves the last bits); a restart must continue the stored state itself."""
    from isoflow._solve import RunState, check_restart

    prob, y0 = iso.models.mhd_sphere(N=5, lmax=3)
    sol = iso.solve(prob, iso.IsoMP(), y0, dt=0.05, n_steps=30, save_every=1)
    alg = prob.algebra
    moved = [y for y in sol.ys if alg.project(y).tobytes() != y.tobytes()]
    assert moved  # the case that needs it
    y = moved[0]
    restart = check_restart(prob, iso.IsoMP(), RunState(3, y, None), t0=0.0, dt=0.05,
                            n_steps=30, save_every=1)  # fmt: skip
    assert restart.state.y.tobytes() == y.tobytes()
    with pytest.raises(iso.NotInSpaceError, match="checkpoint state is not in su"):
        check_restart(prob, iso.IsoMP(), RunState(3, y + 1e-3, None), t0=0.0, dt=0.05,
                      n_steps=30, save_every=1)  # fmt: skip
