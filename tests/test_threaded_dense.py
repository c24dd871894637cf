"""A single large complex system on numba threads, and subnormals flushed in its products
(the dense stages and the BLAS pair layout).

* From ``n = THREADED_MIN_N`` a single complex system's planar stage runs its products and
  passes over numba threads in pieces fixed by ``n`` alone: the states do not depend on the
  thread count (bit for bit), they agree with the serial stage an ensemble member runs to
  rounding, and a number of cores goes to numba (one BLAS thread), as for every run whose
  steps run on numba threads (a long spin chain too); a run that asks for nothing runs the
  pieces on one thread.
* The dense BLAS stages flush subnormal results and operands to zero inside their products
  (x86-64): the caller's floating-point control word is the same after a solve, the bits are
  set inside, and a state whose entries fall to 1e-300 steps as the NumPy path does (so does
  an MHD pair on the BLAS pair layout, which flushes inside its six products).
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

import isoflow as iso
from isoflow._compiled import dense, subnormals
from isoflow.threads import available_cores

two_cores = pytest.mark.skipif(available_cores() < 2, reason="needs 2 cores")
N = dense.THREADED_MIN_N


def _sphere(n: int = N) -> tuple[Any, Any, float]:
    prob, W0 = iso.models.euler_sphere(N=n, seed=1)
    return prob, W0, float(0.3 / np.linalg.norm(prob.B(W0), 2))


def test_the_layout_is_threaded_for_one_large_complex_system_only() -> None:
    prob, W0, h = _sphere()
    one = iso.solve(prob, iso.IsoMP(), W0, dt=h, n_steps=1, progress=False)
    assert one.stats.runner == f"compiled, dense su({N}) (BLAS, real planes, threaded)"
    pair = iso.solve(prob, iso.IsoMP(), np.stack([W0, W0]), dt=h, n_steps=1, progress=False)
    assert pair.stats.runner == f"compiled, dense su({N}) (BLAS, real planes)"
    small, W_small, h_small = _sphere(N // 2)
    below = iso.solve(small, iso.IsoMP(), W_small, dt=h_small, n_steps=1, progress=False)
    assert "threaded" not in below.stats.runner


@two_cores
def test_states_do_not_depend_on_the_threads_and_agree_with_the_serial_stage() -> None:
    prob, W0, h = _sphere()
    runs = {
        th: iso.solve(prob, iso.IsoMP(), W0, dt=h, n_steps=6, progress=False, threads=th)
        for th in (1, 2)
    }
    assert runs[1].stats.threads["numba"] == 1
    assert runs[2].stats.threads == {"cores": available_cores(), "numba": 2, "blas": 1}
    np.testing.assert_array_equal(runs[1].ys, runs[2].ys)
    assert runs[1].stats.iterations_mean == runs[2].stats.iterations_mean
    # the same steps as an ensemble's member (the serial stage, whole products)
    pair = iso.solve(prob, iso.IsoMP(), np.stack([W0, W0]), dt=h, n_steps=6, progress=False)
    scale = np.abs(runs[1].ys[-1]).max()
    assert np.abs(pair.ys[-1, 0] - runs[1].ys[-1]).max() <= 1e-13 * scale
    assert runs[2].diagnostics.casimir_drift < 1e-13


@two_cores
def test_by_default_one_thread_and_more_only_when_asked() -> None:
    # its pieces are split in equal shares: a thread sharing its core with another process
    # would hold up every pass, so a run that asks for nothing runs them on one thread
    prob, W0, h = _sphere()
    kw: dict[str, Any] = {"dt": h, "n_steps": 1, "progress": False}
    assert iso.solve(prob, iso.IsoMP(), W0, **kw).stats.threads["numba"] == 1
    assert iso.solve(prob, iso.IsoMP(), W0, threads={"numba": 2}, **kw).stats.threads == {
        "cores": available_cores(), "numba": 2, "blas": 1,
    }  # fmt: skip
    with iso.threads.thread_limits(blas=1, numba=2):
        assert iso.solve(prob, iso.IsoMP(), W0, **kw).stats.threads["numba"] == 2


@two_cores
def test_a_long_spin_chain_asked_for_two_cores_gets_two_numba_threads() -> None:
    from isoflow._compiled.spin_chain import PARALLEL_MIN_SPINS

    prob, W0 = iso.models.heisenberg_chain(PARALLEL_MIN_SPINS, initial="random", seed=0)
    two = iso.solve(prob, iso.IsoMP(), W0, dt=0.05, n_steps=2, progress=False, threads=2)
    assert "threaded sweeps" in two.stats.runner
    assert two.stats.threads == {"cores": available_cores(), "numba": 2, "blas": 1}
    one = iso.solve(prob, iso.IsoMP(), W0, dt=0.05, n_steps=2, progress=False, threads=1)
    assert one.stats.threads["numba"] == 1
    np.testing.assert_array_equal(one.ys, two.ys)


# ---- subnormals ---------------------------------------------------------------------------------

flushes = pytest.mark.skipif(not subnormals.flushes, reason="x86-64 only")


@flushes
def test_the_flush_bits_are_set_inside_and_restored_after() -> None:
    import numba

    @numba.njit
    def inside() -> Any:
        old = subnormals.flush_on()
        word = subnormals.control_word()
        subnormals.flush_restore(old)
        return word

    before = subnormals.control_word()
    assert before & subnormals.FLUSH_BITS == 0
    assert inside() & subnormals.FLUSH_BITS == subnormals.FLUSH_BITS
    assert subnormals.control_word() == before
    prob, W0, h = _sphere()
    iso.solve(prob, iso.IsoMP(), W0, dt=h, n_steps=2, progress=False)
    assert subnormals.control_word() & subnormals.FLUSH_BITS == 0
    assert np.float64(1e-200) * np.float64(1e-120) > 0  # NumPy still sees subnormals


def _banded(n: int, decay: float, seed: int) -> Any:
    """A state of su(n) whose entries fall off as ``exp(-decay |i - j|)`` (to 1e-300)."""
    alg = iso.algebras.su(n)
    i, j = np.indices((n, n))
    W = alg.random(seed=seed) * np.exp(-decay * np.abs(i - j))
    return alg.project(W)


@pytest.mark.parametrize("n", [64, N])
def test_a_state_with_subnormal_products_steps_as_the_numpy_path_does(n: int) -> None:
    W0 = _banded(n, 700.0 / n, seed=3)
    assert np.abs(W0).min() < 1e-290  # entries whose products are subnormal
    prob, _ = iso.models.euler_sphere(N=n, seed=1)
    h = float(0.2 / np.linalg.norm(prob.B(W0), 2))
    fast = iso.solve(prob, iso.IsoMP(), W0, dt=h, n_steps=3, progress=False)
    assert fast.stats.runner.startswith("compiled")
    python_B = iso.IsospectralProblem(algebra=prob.algebra, B=prob.B)  # no kernel: NumPy
    numpy_path = iso.solve(python_B, iso.IsoMP(), W0, dt=h, n_steps=3, progress=False)
    assert numpy_path.stats.runner == "NumPy"
    scale = np.abs(numpy_path.ys[-1]).max()
    assert np.abs(fast.ys[-1] - numpy_path.ys[-1]).max() <= 1e-13 * scale
    assert fast.diagnostics.casimir_drift < 1e-13


@flushes
def test_mhd_pairs_with_subnormal_products_step_as_the_numpy_path_does() -> None:
    """The BLAS pair layout (MHD on the sphere) flushes inside its products: a band-limited
    pair whose products are subnormal steps as the NumPy path does, and the caller's control
    word is what it was."""
    n = 64
    prob, _ = iso.models.mhd_sphere(N=n, seed=1)
    y0 = np.stack([_banded(n, 700.0 / n, seed=4), _banded(n, 700.0 / n, seed=5)])
    assert np.abs(y0).min() < 1e-290
    B0 = prob.evaluate_B(y0)
    h = 0.2 / max(float(np.linalg.norm(B0[0], 2)), float(np.linalg.norm(B0[1], 2)))
    before = subnormals.control_word()
    fast = iso.solve(prob, iso.IsoMP(), y0, dt=h, n_steps=3, progress=False)
    assert subnormals.control_word() == before
    assert fast.stats.runner.startswith("compiled, dual pairs") and "BLAS" in fast.stats.runner
    python_B = iso.IsospectralProblem(algebra=prob.algebra, B=prob.B)  # no kernel: NumPy
    numpy_path = iso.solve(python_B, iso.IsoMP(), y0, dt=h, n_steps=3, progress=False)
    assert numpy_path.stats.runner == "NumPy"
    scale = np.abs(numpy_path.ys[-1]).max()
    assert np.abs(fast.ys[-1] - numpy_path.ys[-1]).max() <= 1e-13 * scale
    assert float(np.abs(fast.ys[-1] - y0).max()) > 1e-6 * scale  # moved far more than 1e-13
