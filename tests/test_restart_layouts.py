"""A killed run resumes bit for bit on every space and every compiled layout (issue 25).

A restart continues from exactly the state the run held: the checkpoint is checked (space,
finite, shape) but not projected again, since a projection is not idempotent in floating
point for every space (``su(n)``'s trace removal is not). Each case runs once with a write hook
that keeps the file's bytes before every write (the disk a SIGKILL at that write leaves), then
resumes a few of those copies, the one holding only the initial checkpoint among them, and
compares them with the run itself bit for bit. One case is a real SIGKILL of ``isoflow run``.
"""

from __future__ import annotations

import dataclasses
import subprocess
import sys
import textwrap
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest

import isoflow as iso
from helpers import disk_before_each_write
from isoflow import io


def _elementwise(alg: Any, *, skew: bool, frame: bool = False, seed: int = 0) -> Any:
    """``B = C o W`` (in a random unitary frame if asked) on ``alg``: ``C`` symmetric on the
    skew spaces, antisymmetric on ``Sym``/``Herm`` (so that ``B`` is in the normalizer)."""
    rng = np.random.default_rng(seed)
    n = alg.shape[0]
    A = rng.standard_normal((n, n))
    C = A + A.T if skew else A - A.T
    U = None
    if frame:
        Z = rng.standard_normal((n, n))
        if alg.is_complex:
            Z = Z + 1j * rng.standard_normal((n, n))
        U, _ = np.linalg.qr(Z)
    problem = iso.IsospectralProblem(algebra=alg, kernel=iso.ElementwiseLinear(C, frame=U))
    return problem, alg.random(seed + 1)


def _ensemble(y0: Any, alg: Any, members: int) -> Any:
    """``members`` perturbed copies of ``y0``."""
    rng = np.random.default_rng(5)
    return np.stack([alg.project(y0 + 1e-2 * alg.random(rng)) for _ in range(members)])


def _euler(N: int, *, kernel: bool = True) -> tuple[Any, Any]:
    problem, y0 = iso.models.euler_sphere(N=N, seed=3)
    return (problem if kernel else dataclasses.replace(problem, kernel=None)), y0


def _vortices() -> tuple[Any, Any]:
    x = np.random.default_rng(6).standard_normal((4, 3))
    x /= np.linalg.norm(x, axis=1, keepdims=True)
    return iso.models.sphere_vortices(positions=x, circulations=[1.0, 0.5, -0.7, 0.3])


def _blocked() -> tuple[Any, Any]:
    problem, y0 = _elementwise(iso.algebras.su(5), skew=True)
    return problem, _ensemble(y0, problem.algebra, 9)  # blocks of members, one partly filled


def _composed() -> tuple[Any, Any]:
    problem, y0 = _elementwise(iso.algebras.so(4), skew=True)
    return problem, _ensemble(y0, problem.algebra, 3)


def _python_b(alg: Any, power: int) -> tuple[Any, Any]:
    """``B = W^power`` as a Python function on ``alg`` (odd powers stay in ``sp(n)``)."""
    problem = iso.IsospectralProblem(algebra=alg, B=lambda W: np.linalg.matrix_power(W, power))
    return problem, alg.random(1, scale=0.5)


def _chain() -> tuple[Any, Any]:
    return iso.models.heisenberg_chain(12, initial="random", seed=4)


#: name -> (problem and initial state, method); "NumPy" in the name: no compiled path.
CASES: dict[str, tuple[Callable[[], tuple[Any, Any]], Callable[[], iso.Method]]] = {
    "so(5) dense": (lambda: _elementwise(iso.algebras.so(5), skew=True), iso.IsoMP),
    "u(4) dense": (lambda: _elementwise(iso.algebras.u(4), skew=True), iso.IsoMP),
    "su(16) dense": (lambda: _euler(16), iso.IsoMP),
    "su(17) BLAS": (lambda: _euler(17), iso.IsoMP),
    "sym(5) dense": (lambda: _elementwise(iso.algebras.sym(5), skew=False), iso.IsoMP),
    "herm(4) frame": (
        lambda: _elementwise(iso.algebras.herm(4), skew=False, frame=True),
        iso.IsoMP,
    ),
    "su(8) frame": (lambda: _elementwise(iso.algebras.su(8), skew=True, frame=True), iso.IsoMP),
    "su(5) blocked ensemble": (_blocked, iso.IsoMP),
    "so(4) composition ensemble": (_composed, lambda: iso.Composition(iso.IsoMP(), "suzuki-4")),
    "(R^3,x)^N particles": (lambda: iso.models.spin_lattice((3, 3), seed=2), iso.IsoMP),
    "spin chain (fused)": (_chain, iso.IsoMP),
    "spin chain, spherical midpoint": (_chain, iso.SphericalMidpoint),
    "point vortices (sphere)": (_vortices, iso.IsoMP),
    "point vortices (sphere), spherical midpoint": (_vortices, iso.SphericalMidpoint),
    "point vortices (hyperbolic)": (lambda: iso.models.hyperbolic_vortices(1), iso.IsoMP),
    "se(3) pairs (heavy top)": (lambda: iso.models.heavy_top(top="kovalevskaya"), iso.IsoMP),
    "su(17) x| su(17)* BLAS pairs (MHD)": (
        lambda: iso.models.mhd_sphere(N=17, lmax=4, seed=1),
        iso.IsoMP,
    ),
    "su(17) BLAS, least-squares start": (
        lambda: _euler(17),
        lambda: iso.IsoMP(extrapolation_order=3, extrapolation_window=9),
    ),
    "su(16) dense, least-squares start": (
        lambda: _euler(16),
        lambda: iso.IsoMP(extrapolation_order=2, extrapolation_window=7),
    ),
    "su(17) BLAS, Cayley update": (
        lambda: _euler(17),
        lambda: iso.IsoMP(update="cayley", solver=iso.FixedPoint(rtol=1e-8)),
    ),
    "su(17) BLAS, stochastic Cayley update": (
        lambda: iso.models.euler_sphere(N=17, seed=1, noise=0.02, noise_seed=2),
        lambda: iso.StochasticIsoMP(update="cayley"),
    ),
    "spin chain (fused), Cayley update": (_chain, lambda: iso.IsoMP(update="cayley")),
    "(R^3,x)^N thermal particles, stochastic Cayley update": (
        lambda: iso.models.spin_lattice((3, 3), seed=2, temperature=0.4, damping=0.1, noise_seed=5),
        lambda: iso.StochasticIsoMP(update="cayley"),
    ),
    "su(5) lanes ensemble, Cayley update": (
        _blocked,
        lambda: iso.IsoMP(update="cayley", solver=iso.FixedPoint(rtol=1e-8)),
    ),
    "so(5) dense, Cayley update": (
        lambda: _elementwise(iso.algebras.so(5), skew=True),
        lambda: iso.IsoMP(update="cayley", solver=iso.FixedPoint(rtol=1e-8)),
    ),
    "su(6) NumPy": (lambda: _euler(6, kernel=False), iso.IsoMP),
    "sp(2) NumPy": (lambda: _python_b(iso.algebras.sp(2), 3), iso.IsoMP),
    "gl(3) NumPy": (lambda: _python_b(iso.algebras.gl(3), 2), iso.IsoMP),
}

N_STEPS, SAVE_EVERY = 36, 2


def _run_keeping_copies(
    problem: Any, method: iso.Method, y0: Any, path: Path
) -> tuple[iso.Solution, list[bytes]]:
    """Run into ``path``, keeping the file's bytes before each write after it was published."""
    with disk_before_each_write(path) as copies:
        sol = iso.solve(
            problem, method, y0, dt=0.01, n_steps=N_STEPS, save_every=SAVE_EVERY, progress=False,
            writer=io.HDF5Writer(path, chunk_rows=2, flush_seconds=0.0),
        )  # fmt: skip
    return sol, copies


@pytest.mark.parametrize("case", list(CASES))
def test_a_kill_at_any_write_resumes_bit_for_bit(tmp_path: Path, case: str) -> None:
    make, make_method = CASES[case]
    (problem, y0), method = make(), make_method()
    sol, copies = _run_keeping_copies(problem, method, y0, tmp_path / "run.h5")
    assert sol.success, sol.message
    assert ("NumPy" in sol.stats.runner) == ("NumPy" in case), sol.stats.runner
    ref = io.load(tmp_path / "run.h5")
    rng = np.random.default_rng(len(case))
    picks = sorted({0, *(int(i) for i in rng.integers(1, len(copies), 3))})
    steps = []
    for i in picks:
        path = tmp_path / f"kill{i}.h5"
        path.write_bytes(copies[i])
        part = io.load(path)
        steps.append(part.step)
        assert part.ys.tobytes() == ref.ys[: len(part.ys)].tobytes()
        resumed = io.resume(path, problem=problem, method=method, progress=False)
        assert resumed.success, resumed.message
        got = io.load(path)
        assert got.complete and got.step == N_STEPS
        assert got.ys.tobytes() == ref.ys.tobytes(), (case, part.step)
        assert got.ts.tobytes() == ref.ts.tobytes() and got.drifts == ref.drifts
    assert steps[0] == 0 and max(steps) > 0, steps


def test_the_checkpoint_is_not_projected_again() -> None:
    """The mechanism: su(n)'s projection is not idempotent, and a restart does not apply it."""
    alg = iso.algebras.su(16)
    # whether a state moves under a second projection depends on its bits (the trace's
    # rounding, so on numpy's summation too): take the first of a few that does
    states = (alg.project(1.1 * alg.random(seed)) for seed in range(50))
    W = next((V for V in states if alg.project(V).tobytes() != V.tobytes()), None)
    assert W is not None  # what made restarts drift
    assert alg.validate(W, project=False).tobytes() == W.tobytes()
    problem, _y0 = _euler(16)
    method = iso.IsoMP()
    restart = iso._solve.check_restart(
        problem, method, iso._solve.RunState(0, W), t0=0.0, dt=0.01, n_steps=4, save_every=1
    )
    assert restart.state.y.tobytes() == W.tobytes()
    with pytest.raises(iso.NotInSpaceError, match="checkpoint state is not in su"):
        iso._solve.check_restart(
            problem, method, iso._solve.RunState(0, W + np.eye(16)), t0=0.0, dt=0.01,
            n_steps=4, save_every=1,
        )  # fmt: skip


def test_resume_evaluates_b_once_to_check_the_restart(tmp_path: Path) -> None:
    seen: list[bytes] = []
    base, y0 = iso.models.rigid_body(n=4)

    def B(W: Any) -> Any:
        seen.append(np.asarray(W).tobytes())
        return base.B(W)

    problem = iso.IsospectralProblem(B=B, algebra=base.algebra)
    path = tmp_path / "b.h5"
    iso.solve(problem, iso.IsoMP(), y0, dt=0.01, n_steps=4, progress=False,
              writer=io.HDF5Writer(path))  # fmt: skip
    seen.clear()
    io.resume(path, problem=problem, method=iso.IsoMP(), progress=False)  # a complete run
    assert seen.count(io.load(path).y_final.tobytes()) == 1  # the checkpoint state's check


# ---- a real SIGKILL of isoflow run (su(16), the reproduction of issue 25) ----------------------

EULER = [
    "run", "euler-sphere", "--N", "16", "--dt", "0.02", "--n-steps", "400", "--save-every", "5",
    "--chunk-rows", "4", "--flush-seconds", "1e-9", "--quiet",
]  # fmt: skip

_STALL = textwrap.dedent(
    """
    import sys, time
    from pathlib import Path
    from isoflow.io import safefile
    out, ready, writes = Path(sys.argv[1]), Path(sys.argv[2]), int(sys.argv[3])
    seen = [0]
    def hook(sf, offset, data):
        seen[0] += out.exists()  # writes after the file was published
        if seen[0] == writes:  # stop before this write, tell the test, wait for the kill
            ready.write_text("stalled")
            while True:
                time.sleep(60)
    safefile.write_hook = hook
    from isoflow.cli import main
    sys.exit(main(sys.argv[4:]))
    """
)


def test_sigkill_of_an_su_n_run_then_resume_is_bit_for_bit(tmp_path: Path) -> None:
    ref_path = tmp_path / "ref.h5"
    cfg = iso.registry.normalize_config(
        {"model": "euler-sphere", "params": {"N": 16}, "dt": 0.02, "n_steps": 400,
         "save_every": 5}
    )  # fmt: skip
    problem, y0, method, kw = iso.registry.build(cfg)
    iso.solve(problem, method, y0, **kw, progress=False,
              writer=io.HDF5Writer(ref_path, cfg))  # fmt: skip
    ref = io.load(ref_path)
    path, ready = tmp_path / "killed.h5", tmp_path / "stalled"
    writes = int(np.random.default_rng(25).integers(60, 180))  # of about 690: steps 5 to 65
    proc = subprocess.Popen(
        [sys.executable, "-c", _STALL, str(path), str(ready), str(writes), *EULER,
         "--out", str(path)],
        stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
    )  # fmt: skip
    deadline = time.monotonic() + 600  # a guard against a hang, not a timing
    while not ready.exists() and proc.poll() is None and time.monotonic() < deadline:
        time.sleep(0.02)
    stalled = ready.exists()
    proc.kill()
    _, err = proc.communicate()
    assert stalled, err[-2000:]
    part = io.load(path)
    assert 0 < part.step < 400 and not part.complete
    assert part.ys.tobytes() == ref.ys[: len(part.ys)].tobytes()
    from isoflow.cli import main

    assert main(["run", "--resume", str(path), "--quiet"]) == 0  # as a user resumes it
    got = io.load(path)
    assert got.complete and got.ys.tobytes() == ref.ys.tobytes() and got.drifts == ref.drifts
