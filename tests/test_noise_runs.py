"""Stochastic runs repeat their paths bit for bit: after a kill and a resume, and as the tasks
of a sweep against one ensemble of all its members (issue 22)."""

from __future__ import annotations

import re
import subprocess
from pathlib import Path

import numpy as np
import pytest

import isoflow as iso
from cli_helpers import isoflow_cmd as _cmd
from cli_helpers import kill_when as _kill_when
from cli_helpers import one_error_line, run_cli_here
from isoflow import io

ARGS = [
    "run", "rigid-body", "--n", "4", "--noise", "0.3", "--noise-seed", "11",
    "--method", "stochastic-isomp", "--dt", "0.005", "--n-steps", "16000", "--save-every", "4",
    "--chunk-rows", "16", "--flush-seconds", "0.05", "--quiet",
]  # fmt: skip


def test_a_killed_stochastic_run_resumes_on_the_same_path_bit_for_bit(tmp_path: Path) -> None:
    full = tmp_path / "full.h5"
    out = subprocess.run(_cmd(*ARGS, "--out", str(full)), capture_output=True, text=True)
    assert out.returncode == 0, out.stderr
    ref = io.load(full)
    assert io.info(full)["config"]["params"]["noise_seed"] == 11  # the seed is in the file
    path = tmp_path / "killed.h5"
    proc = subprocess.Popen(_cmd(*ARGS, "--out", str(path)), stderr=subprocess.DEVNULL)
    _kill_when(path, 100, proc)
    assert not io.load(path).complete
    out = subprocess.run(
        _cmd("run", "--resume", str(path), "--quiet"), capture_output=True, text=True
    )  # the problem and its noise rebuilt from the file's configuration
    assert out.returncode == 0, out.stderr
    got = io.load(path)
    assert got.complete and got.ys.tobytes() == ref.ys.tobytes()


def test_the_tasks_of_a_sweep_draw_what_one_ensemble_of_its_members_draws(tmp_path: Path) -> None:
    from isoflow.sweep import read_spec, run_task
    from isoflow.sweep.files import task_paths, write_manifest
    from isoflow.sweep.task import build_member, task_layouts

    spec = read_spec({
        "model": "rigid-body", "params": {"n": 3, "noise": 0.4, "noise_seed": 3},
        "method": "stochastic-isomp", "dt": 0.02, "n_steps": 60, "save_every": 6,
        "perturb": 1e-3, "members_per_task": 2, "grid": {"seed": {"start": 0, "stop": 4}},
    })  # fmt: skip
    assert len(spec.tasks) == 2
    write_manifest(tmp_path, spec, task_layouts(spec))
    for t in spec.tasks:
        run_task(spec, t.id, tmp_path)
    built = [build_member(spec, m) for m in spec.members]
    problem = built[0][0]  # ids 0..3: the members' indices in the sweep
    whole = iso.solve(problem, iso.StochasticIsoMP(), np.stack([y for _, y in built]),
                      dt=0.02, n_steps=60, save_every=6, progress=False)  # fmt: skip
    for t in spec.tasks:
        ys = io.load(task_paths(tmp_path, t.id).h5).ys
        idx = [m.index for m in t.members]
        assert ys.tobytes() == whole.ys[:, idx].tobytes()
    assert not np.array_equal(whole.ys[-1, 0], whole.ys[-1, 2])


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--noise", "0.3", "--method", "stochastic-isomp"], "rigid_body: noise_seed is required"),
        (["--noise", "0.3", "--noise-seed", "1"],
         "transport noise, which IsoMP would ignore: .* \\(method 'stochastic-isomp'\\)"),
    ],
)  # fmt: skip
def test_noise_mistakes_on_the_command_line_are_one_line_errors(
    tmp_path: Path, args: list[str], message: str
) -> None:
    res = run_cli_here("run", "rigid-body", "--n", "3", *args, "--dt", "0.1", "--n-steps",
                       "2", "--out", "x.h5", "--quiet", cwd=tmp_path)  # fmt: skip
    assert res.returncode == 1
    assert re.search(message, one_error_line(res.stderr)), res.stderr
    assert not (tmp_path / "x.h5").exists()


def test_noise_with_dissipation_runs_as_the_split_step_of_stochastic_isomp(tmp_path: Path) -> None:
    """The default method's split step would drop the noise: a one-line error; with
    ``--method stochastic-isomp`` the run is ``Strang(StochasticIsoMP())`` and its states
    leave the path without noise."""
    common = ["run", "euler-sphere", "--N", "6", "--viscosity", "0.01", "--dt", "0.05",
              "--n-steps", "4", "--quiet"]  # fmt: skip
    noisy = ["--noise", "0.1", "--noise-seed", "2"]
    res = run_cli_here(*common, *noisy, "--out", "x.h5", cwd=tmp_path)
    assert res.returncode == 1
    assert re.search(
        r"transport noise, which Strang\(IsoMP\) would ignore: integrate it with "
        r"iso.Strang\(iso.StochasticIsoMP\(\)\)",
        one_error_line(res.stderr),
    ), res.stderr
    assert not (tmp_path / "x.h5").exists()
    res = run_cli_here(*common, *noisy, "--method", "stochastic-isomp", "--out", "s.h5",
                       cwd=tmp_path)  # fmt: skip
    assert res.returncode == 0, res.stderr
    res = run_cli_here(*common, "--out", "d.h5", cwd=tmp_path)
    assert res.returncode == 0, res.stderr
    s, d = io.load(tmp_path / "s.h5"), io.load(tmp_path / "d.h5")
    assert io.info(tmp_path / "s.h5")["meta"]["method"] == "Strang(stochastic IsoMP)"
    assert np.max(np.abs(s.ys[-1] - d.ys[-1])) > 1e-4
