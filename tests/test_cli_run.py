"""``isoflow run / info / plot / reproduce`` through the real entry point, and user mistakes."""

from __future__ import annotations

import json
import re
from pathlib import Path

import h5py
import numpy as np
import pytest

from cli_helpers import run_cli as _run
from cli_helpers import run_cli_here
from isoflow import io


def test_run_info_plot(tmp_path: Path) -> None:
    out = tmp_path / "rb.h5"
    res = _run(
        "run",
        "rigid-body",
        "--n",
        "6",
        "--dt",
        "0.1",
        "--t1",
        "20",
        "--save-every",
        "10",
        "--out",
        str(out),
        "--quiet",
    )
    assert res.returncode == 0, res.stderr
    assert "200 of 200" in res.stdout
    run = io.load(out)
    assert len(run.ys) == 21 and run.config["params"] == {"n": 6}
    assert run.drifts["casimir_drift"] < 1e-13
    info = _run("info", str(out))
    assert info.returncode == 0 and "complete" in info.stdout and "rigid-body" in info.stdout
    js = json.loads(_run("info", str(out), "--json").stdout)
    assert js["n_saved"] == 21 and js["complete"] and js["drifts"]["casimir_drift"] < 1e-13
    png = tmp_path / "rb.png"
    res = _run("plot", str(out), "--out", str(png))
    assert res.returncode == 0, res.stderr
    assert png.read_bytes()[:4] == b"\x89PNG"


def test_run_from_toml_matches_options(tmp_path: Path) -> None:
    toml = tmp_path / "run.toml"
    toml.write_text(
        'model = "spin-chain"\nmethod = "spherical-midpoint"\ndt = 0.05\nn_steps = 40\n'
        'save_every = 4\nout = "chain.h5"\n[params]\nN = 12\n'
    )
    res = _run("run", "--config", str(toml), "--quiet", cwd=tmp_path)
    assert res.returncode == 0, res.stderr
    res2 = _run(
        "run",
        "spin-chain",
        "--N",
        "12",
        "--method",
        "spherical-midpoint",
        "--dt",
        "0.05",
        "--n-steps",
        "40",
        "--save-every",
        "4",
        "--out",
        "opts.h5",
        "--quiet",
        cwd=tmp_path,
    )
    assert res2.returncode == 0, res2.stderr
    a, b = io.load(tmp_path / "chain.h5"), io.load(tmp_path / "opts.h5")
    assert a.meta["method"] == "spherical midpoint"
    assert np.array_equal(a.ys, b.ys) and a.config == b.config


@pytest.fixture(scope="module")
def mistakes_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    tmp_path = tmp_path_factory.mktemp("mistakes")
    (tmp_path / "bad.toml").write_text('model = "rigid-body"\ndt = [0.1\n')
    (tmp_path / "unknown_key.toml").write_text('model = "rigid-body"\ndt = 0.1\ncolour = 3\n')
    (tmp_path / "text.h5").write_text("not hdf5")
    with h5py.File(tmp_path / "other.h5", "w") as f:
        f["x"] = np.arange(3)
    good = _run(
        "run",
        "rigid-body",
        "--n",
        "3",
        "--dt",
        "0.1",
        "--n-steps",
        "30",
        "--out",
        "good.h5",
        "--quiet",
        cwd=tmp_path,
    )
    assert good.returncode == 0, good.stderr
    data = (tmp_path / "good.h5").read_bytes()
    (tmp_path / "cut.h5").write_bytes(data[: len(data) // 2])
    return tmp_path


@pytest.mark.parametrize(
    ("args", "code", "pattern"),
    [
        (
            ["run", "pendulum", "--dt", "0.1", "--t1", "1", "--out", "x.h5"],
            1,
            r"unknown model 'pendulum'",
        ),
        (
            ["run", "rigid-body", "--dt", "0.1", "--t1", "1", "--out", "x.h5", "--frob", "1"],
            2,
            r"unrecognized arguments: --frob",
        ),
        (
            ["run", "rigid-body", "--N", "3", "--dt", "0.1", "--t1", "1", "--out", "x.h5"],
            1,
            r"model 'rigid-body' has no parameter 'N'",
        ),
        (
            ["run", "rigid-body", "--n", "ten", "--dt", "0.1", "--t1", "1", "--out", "x.h5"],
            1,
            r"rigid-body n must be an integer",
        ),
        (["run", "rigid-body", "--dt", "0.1", "--out", "x.h5"], 1, r"exactly two of"),
        (["run", "rigid-body", "--dt", "0.1", "--t1", "1"], 1, r"--out FILE"),
        (
            ["run", "rigid-body", "--method", "euler", "--dt", "0.1", "--t1", "1", "--out", "x.h5"],
            1,
            r"unknown method 'euler'",
        ),
        (["run", "--config", "missing.toml"], 1, r"no such configuration file"),
        (["run", "--config", "bad.toml"], 1, r"malformed TOML"),
        (["run", "--config", "unknown_key.toml"], 1, r"unknown option\(s\) colour"),
        (["run", "--resume", "missing.h5"], 1, r"no such file"),
        (["info", "text.h5"], 1, r"not an isoflow result file"),
        (["info", "other.h5"], 1, r"not an isoflow result file"),
        (["info", "cut.h5"], 1, r"truncated"),
        (["plot", "good.h5", "--out", "fig.bmp"], 1, r"choose a .png, .pdf or .svg"),
        (
            ["plot", "good.h5", "--out", "nodir/fig.png"],
            1,
            r"nodir/fig.png: no directory nodir to write it in$",
        ),
        (
            ["run", "rigid-body", "--dt", "0.1", "--t1", "1", "--out", "good.h5"],
            1,
            r"good.h5 exists \(use --force",
        ),
        (["reproduce", "spin-chain-errors"], 2, r"invalid choice"),
        (
            ["run", "rigid-body", "--dt", "0.3", "--t1", "1", "--out", "y.h5"],
            1,
            r"not a whole number of steps",
        ),
    ],
)
def test_user_mistakes(mistakes_dir: Path, args: list[str], code: int, pattern: str) -> None:
    tmp_path = mistakes_dir
    res = run_cli_here(*args, cwd=tmp_path)
    assert res.returncode == code, res.stderr
    assert "Traceback" not in res.stderr
    assert re.search(pattern, res.stderr), res.stderr
    lines = [ln for ln in res.stderr.strip().splitlines() if ln.startswith("isoflow")]
    assert len(lines) == 1 and "error" in lines[0]


@pytest.mark.parametrize(
    "args",
    [
        ["run", "pendulum", "--dt", "0.1", "--t1", "1", "--out", "x.h5"],
        ["run", "rigid-body", "--dt", "0.1", "--t1", "1", "--out", "x.h5", "--frob", "1"],
        ["run", "rigid-body", "--dt", "-0.1", "--n-steps", "3", "--out", "x.h5"],
        ["info", "cut.h5"],
    ],
)
def test_the_installed_command_says_what_the_in_process_entry_point_says(
    mistakes_dir: Path, args: list[str]
) -> None:
    """The mistakes above run in this process (:func:`cli_helpers.run_cli_here`); the
    ``isoflow`` script gives the same exit status and the same stderr."""
    here = run_cli_here(*args, cwd=mistakes_dir)
    script = _run(*args, cwd=mistakes_dir)
    assert (script.returncode, script.stderr) == (here.returncode, here.stderr)
    assert here.returncode in (1, 2)
    assert re.match(r"isoflow( run)?: error: ", here.stderr), here.stderr
    assert len(here.stderr.strip().splitlines()) == 1  # no usage block
