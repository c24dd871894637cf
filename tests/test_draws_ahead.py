"""Step data drawn ahead (:mod:`isoflow._compiled.draws_ahead`): a chunk of a single system's
stochastic run is cut into pieces whose noise is drawn on another thread while the compiled
loop runs the piece before. The results must not change by a bit: every case runs with the
default thread plan (the pieces) and with ``threads=1`` (one undivided call a chunk), and the
pieces are checked to have been taken."""

from __future__ import annotations

import threading
from concurrent.futures import ThreadPoolExecutor

import numpy as np
import pytest

import isoflow as iso
import user_kernels as uk
from isoflow import io
from isoflow._compiled import draws_ahead as ahead
from isoflow._compiled import runner as compiled_runner
from isoflow.noise import TransportNoise
from isoflow.threads import available_cores

needs_two_cores = pytest.mark.skipif(
    available_cores() < 2, reason="the draws go ahead only with a core to spare"
)


def test_pieces_cover_the_chunk_with_a_short_first_piece() -> None:
    for nsteps in range(1, 300):
        sizes = ahead.pieces(nsteps)
        assert sum(sizes) == nsteps and min(sizes) >= 1, nsteps
        assert sizes[0] == max(1, nsteps // 8), nsteps
        assert len(sizes) <= 1 + ahead.MAX_PIECES, nsteps
        rest = sizes[1:]
        assert all(n == rest[0] for n in rest[:-1]) and (not rest or rest[-1] <= rest[0]), nsteps


@pytest.mark.parametrize(
    ("change", "expected"),
    [
        ({}, "ahead"),
        ({"serial_loop": False}, "together"),  # units or sweeps over numba threads
        ({"nsteps": 1}, "inline"),
        ({"values_per_step": ahead.DRAW_AHEAD_MIN_VALUES - 1}, "inline"),
        ({"values_per_step": 0}, "inline"),  # before the run's first draw
        ({"numba_threads": 1}, "inline"),  # threads=1: no second thread
        ({"numba_threads": 1, "serial_loop": False}, "inline"),
        ({"blas_threads": 2}, "inline"),  # BLAS has the other core
    ],
)
def test_the_rule_for_drawing_ahead(change: dict, expected: str) -> None:
    base = {
        "nsteps": 10, "values_per_step": ahead.DRAW_AHEAD_MIN_VALUES, "serial_loop": True,
        "numba_threads": 2, "blas_threads": 1,
    }  # fmt: skip
    assert ahead.how_to_draw(**(base | change)) == expected


def _numbered(k0: int, n: int) -> np.ndarray:
    """Step data that names its steps: ``(n, 2, 3)`` filled with the step's number."""
    return np.broadcast_to(np.arange(k0 + 1, k0 + n + 1.0)[:, None, None], (n, 2, 3)).copy()


@pytest.mark.parametrize("helper", ["none", "before", "beside"])
def test_step_draws_give_the_piece_in_order_whoever_draws_a_step(helper: str) -> None:
    draws = ahead.StepDraws(_numbered, 40, 9)
    if helper == "before":
        draws.help()  # the helper drew every step: the caller finds none left
    elif helper == "beside":
        t = threading.Thread(target=draws.help)
        t.start()
    out = draws.result()
    if helper == "beside":
        t.join()
    np.testing.assert_array_equal(out, _numbered(40, 9))


def test_step_draws_wait_for_the_helpers_step_in_progress() -> None:
    taken, release, caller_done = threading.Event(), threading.Event(), threading.Event()
    caller_steps: list[int] = []

    def draw(k: int, n: int) -> np.ndarray:
        if k == 10:  # the first step: the helper's
            taken.set()
            assert release.wait(60)
        else:
            caller_steps.append(k)
            if len(caller_steps) == 4:
                caller_done.set()
        return _numbered(k, n)

    draws = ahead.StepDraws(draw, 10, 5)
    helper = threading.Thread(target=draws.help)
    helper.start()
    assert taken.wait(60)
    with ThreadPoolExecutor(1) as pool:
        result = pool.submit(draws.result)
        assert caller_done.wait(60)  # the caller drew steps 5..2 from the back
        assert not result.done()  # and waits for step 1, which the helper holds
        release.set()
        np.testing.assert_array_equal(result.result(60), _numbered(10, 5))
    helper.join()
    assert sorted(caller_steps) == [11, 12, 13, 14]


def test_cancelled_step_draws_hand_out_no_more_steps() -> None:
    drawn: list[int] = []

    def draw(k: int, n: int) -> np.ndarray:
        drawn.append(k)
        return _numbered(k, n)

    draws = ahead.StepDraws(draw, 0, 6)
    draws.cancel()
    draws.help()
    assert drawn == []


@pytest.mark.parametrize(("failing", "helper"), [(2, True), (5, False)])
def test_step_draws_raise_an_error_of_either_thread(failing: int, helper: bool) -> None:
    def draw(k: int, n: int) -> np.ndarray:
        if k == failing:
            raise ValueError(f"after step {k}: failed")
        return _numbered(k, n)

    draws = ahead.StepDraws(draw, 0, 7)
    if helper:
        draws.help()  # takes steps from the first until its third raises
    with pytest.raises(ValueError, match=f"after step {failing}: failed"):
        draws.result()  # without a helper: from the last step back, its second raises


@pytest.fixture
def pieces_taken(monkeypatch: pytest.MonkeyPatch) -> list[int]:
    """Every step data counts (the tests' states are small); the chunks cut into pieces are
    counted."""
    monkeypatch.setattr(ahead, "DRAW_AHEAD_MIN_VALUES", 1)
    taken: list[int] = []
    original = compiled_runner.CompiledRunner._call_in_pieces

    def counting(self, nsteps, grid, buf):  # type: ignore[no-untyped-def]
        taken.append(nsteps)
        return original(self, nsteps, grid, buf)

    monkeypatch.setattr(compiled_runner.CompiledRunner, "_call_in_pieces", counting)
    return taken


@pytest.fixture
def drawn_together(monkeypatch: pytest.MonkeyPatch) -> list[int]:
    """Every step data counts; the steps drawn by helper threads are counted, chunk by chunk
    or piece by piece."""
    monkeypatch.setattr(ahead, "DRAW_AHEAD_MIN_VALUES", 1)
    taken: list[int] = []
    original = compiled_runner.CompiledRunner._start_draws

    def counting(self, pool, k0, nsteps):  # type: ignore[no-untyped-def]
        taken.append(nsteps)
        return original(self, pool, k0, nsteps)

    monkeypatch.setattr(compiled_runner.CompiledRunner, "_start_draws", counting)
    return taken


def _both(prob, method, y0, **kw):  # type: ignore[no-untyped-def]
    return (
        iso.solve(prob, method, y0, progress=False, **kw),
        iso.solve(prob, method, y0, progress=False, threads=1, **kw),
    )


def _thermal_lattice():  # type: ignore[no-untyped-def]
    return iso.models.spin_lattice(
        (12, 12), J=-1.0, field=(0.0, 0.0, 0.2), initial="random", seed=0,
        temperature=0.5, damping=0.1, noise_seed=3,
    )  # fmt: skip


def _thermal_chain():  # type: ignore[no-untyped-def]
    return iso.models.heisenberg_chain(
        64, initial="random", seed=1, temperature=0.3, damping=0.2, noise_seed=4
    )


def _noisy_rigid_body():  # type: ignore[no-untyped-def]
    return iso.models.rigid_body(6, noise=0.3, noise_seed=5)


@needs_two_cores
@pytest.mark.parametrize("model", [_thermal_lattice, _thermal_chain, _noisy_rigid_body])
@pytest.mark.parametrize("update", ["midpoint", "cayley"])
def test_pieces_give_the_undivided_run_bit_for_bit(
    pieces_taken: list[int], model, update: str
) -> None:  # type: ignore[no-untyped-def]
    prob, y0 = model()
    a, b = _both(prob, iso.StochasticIsoMP(update=update), y0, dt=0.05, n_steps=90, save_every=7)
    assert pieces_taken, "no chunk was cut into pieces"
    assert "compiled" in a.stats.runner
    np.testing.assert_array_equal(a.ys, b.ys)  # saved rows inside pieces included
    np.testing.assert_array_equal(a.ts, b.ts)
    assert a.stats.n_iterations == b.stats.n_iterations
    assert a.stats.iterations_max == b.stats.iterations_max
    assert a.stats.residual_max == b.stats.residual_max


@needs_two_cores
@pytest.mark.parametrize("model", [_thermal_chain, _noisy_rigid_body])
def test_an_ensemble_drawn_together_gives_the_run_drawn_inline_bit_for_bit(
    drawn_together: list[int], monkeypatch: pytest.MonkeyPatch, model
) -> None:  # type: ignore[no-untyped-def]
    calls_in_pieces: list[int] = []
    monkeypatch.setattr(
        compiled_runner.CompiledRunner, "_call_in_pieces",
        lambda self, *a: calls_in_pieces.append(1),
    )  # fmt: skip
    prob, y0 = model()
    ys = np.stack([y0] * 5)  # units over numba threads: the loop uses the cores
    a, b = _both(prob, iso.StochasticIsoMP(), ys, dt=0.05, n_steps=60, save_every=7)
    assert drawn_together and not calls_in_pieces
    np.testing.assert_array_equal(a.ys, b.ys)
    assert a.stats.n_iterations == b.stats.n_iterations
    assert not np.array_equal(a.ys[-1, 0], a.ys[-1, 1])  # each member its own path


@needs_two_cores
def test_a_run_whose_writer_works_beside_its_loop_draws_inline(
    pieces_taken: list[int], drawn_together: list[int]
) -> None:
    """Saving many rows puts the diagnostics on a writer thread: on two cores the writer and
    the loop take both, and the draws stay on the loop's thread."""
    from isoflow._writers import PIPELINE_MIN_ROWS

    prob, y0 = _thermal_lattice()
    n = PIPELINE_MIN_ROWS + 10
    iso.solve(prob, iso.StochasticIsoMP(), y0, dt=0.05, n_steps=n, save_every=n, progress=False)
    assert pieces_taken  # few rows: no writer thread, the draws go ahead
    pieces_taken.clear()
    drawn_together.clear()
    a, b = _both(prob, iso.StochasticIsoMP(), y0, dt=0.05, n_steps=n, save_every=1)
    if available_cores() == 2:
        assert not pieces_taken and not drawn_together
    np.testing.assert_array_equal(a.ys, b.ys)


@needs_two_cores
def test_a_member_that_fails_inside_a_piece_fails_as_in_the_undivided_run(
    pieces_taken: list[int],
) -> None:
    prob, y0 = _noisy_rigid_body()
    method = iso.StochasticIsoMP(solver=iso.FixedPoint(max_iter=12))  # step 54 needs 13
    a, b = _both(prob, method, y0, dt=0.01, n_steps=120, throw=False)
    assert pieces_taken
    assert 5 < int(b.failed_step) < 120  # inside a chunk of several steps
    assert int(a.failed_step) == int(b.failed_step)
    assert a.failure_reasons == b.failure_reasons
    np.testing.assert_array_equal(a.ys, b.ys)


@needs_two_cores
def test_a_field_that_raises_inside_a_piece_fails_as_in_the_undivided_run(
    pieces_taken: list[int],
) -> None:
    alg = iso.algebras.so(5)
    d = np.arange(1.0, 6.0)
    C = 0.5 * (d[:, None] + d[None, :])
    W0 = alg.random(0)
    W0 *= 0.3 / float(np.max(np.abs(W0)))  # the largest entry is 0.3 and moves
    field = alg.random(seed=7)
    prob = iso.IsospectralProblem(
        B=lambda W: C * W, algebra=alg, kernel=iso.CompiledB(uk.raises_when_large, (C, 0.31)),
        noise=TransportNoise(fields=0.05 * field[None] / np.linalg.norm(field), seed=2),
    )  # fmt: skip
    a, b = _both(prob, iso.StochasticIsoMP(), W0, dt=0.1, n_steps=500, save_every=5, throw=False)
    assert pieces_taken
    k = int(b.failed_step)
    assert 5 < k < 500
    assert int(a.failed_step) == k
    assert a.failure_reasons == b.failure_reasons == {(): "B raised: ValueError: entry too large"}
    np.testing.assert_array_equal(a.ys, b.ys)
    assert a.stats.n_iterations == b.stats.n_iterations


@needs_two_cores
def test_an_error_while_drawing_a_later_piece_reaches_the_caller(
    pieces_taken: list[int], monkeypatch: pytest.MonkeyPatch
) -> None:
    prob, y0 = _thermal_chain()
    original = compiled_runner.CompiledRunner._step_data
    calls: list[int] = []

    def failing_later(self, k0, nsteps, members):  # type: ignore[no-untyped-def]
        calls.append(k0)
        if len(calls) > 4:  # the first chunks (1 and 4 steps), then a later piece
            raise RuntimeError("the draws failed")
        return original(self, k0, nsteps, members)

    monkeypatch.setattr(compiled_runner.CompiledRunner, "_step_data", failing_later)
    with pytest.raises(RuntimeError, match="the draws failed"):
        iso.solve(prob, iso.StochasticIsoMP(), y0, dt=0.05, n_steps=90, progress=False)
    assert pieces_taken


def test_a_step_that_cannot_be_stored_is_an_error_not_a_wait() -> None:
    """A step of another shape than the piece's first one fails to store: the error reaches
    the caller, who does not wait for the step forever."""

    def draw(k: int, n: int) -> np.ndarray:
        return np.zeros((n, 2, 4 if k == 2 else 3))

    draws = ahead.StepDraws(draw, 0, 6)
    helper = threading.Thread(target=draws.help)
    helper.start()
    helper.join(60)
    assert not helper.is_alive()
    with ThreadPoolExecutor(1) as pool:
        result = pool.submit(draws.result)
        with pytest.raises(ValueError, match="broadcast"):
            result.result(60)


@needs_two_cores
@pytest.mark.parametrize("model", [_thermal_lattice, _thermal_chain])
def test_each_chunk_begins_with_the_steps_its_predecessor_drew_ahead(
    monkeypatch: pytest.MonkeyPatch, tmp_path, model
) -> None:  # type: ignore[no-untyped-def]
    """While a chunk's last piece runs, the helpers draw the next chunk's first steps: every
    chunk but the first begins with them, none is drawn past the run's last step, and the
    states are those of ``threads=1`` bit for bit."""
    monkeypatch.setattr(ahead, "DRAW_AHEAD_MIN_VALUES", 1)
    ready: list[bool] = []
    last: list[int] = []
    original = compiled_runner.CompiledRunner._call_in_pieces
    start = compiled_runner.CompiledRunner._start_draws

    def spying(self, nsteps, grid, buf):  # type: ignore[no-untyped-def]
        ready.append(self._drawn_next is not None and self._drawn_next[0] == self.k)
        return original(self, nsteps, grid, buf)

    def drawing(self, pool, k0, nsteps):  # type: ignore[no-untyped-def]
        last.append(k0 + nsteps)
        return start(self, pool, k0, nsteps)

    monkeypatch.setattr(compiled_runner.CompiledRunner, "_call_in_pieces", spying)
    monkeypatch.setattr(compiled_runner.CompiledRunner, "_start_draws", drawing)
    prob, y0 = model()
    runs = []
    for name, threads in (("ahead.h5", None), ("inline.h5", 1)):
        # a writer that takes one row a chunk: a chunk ends at every save point (7 steps)
        writer = io.HDF5Writer(tmp_path / name, chunk_rows=1, flush_seconds=0.0)
        iso.solve(prob, iso.StochasticIsoMP(), y0, dt=0.05, n_steps=90, save_every=7,
                  progress=False, threads=threads, writer=writer)  # fmt: skip
        runs.append(io.load(tmp_path / name))
    assert len(ready) >= 10 and not ready[0] and all(ready[1:]), ready
    assert max(last) == 90
    np.testing.assert_array_equal(runs[0].ys, runs[1].ys)
