"""``isoflow run --model package.module:factory`` and entry-point models: run, stream, resume."""

from __future__ import annotations

import importlib.metadata
import re
import subprocess
from pathlib import Path

import numpy as np
import pytest

from cli_helpers import isoflow_cmd, kill_when, one_error_line, run_cli, run_cli_here, user_env
from helpers import disk_before_each_write, write_user_model
from isoflow import cli, io, registry

TOY = "user_models:toy_rigid_body"
ARGS = ["--dt", "0.01", "--n-steps", "20000", "--save-every", "3", "--chunk-rows", "16",
        "--flush-seconds", "0.05", "--quiet"]  # fmt: skip


def test_user_model_streams_and_resumes_bit_for_bit_when_named_again(tmp_path: Path) -> None:
    env = user_env()
    model = ["run", "--model", TOY, "--param", "n=4", "--param", "scale=0.5"]
    full = run_cli(*model, *ARGS, "--out", "full.h5", cwd=tmp_path, env=env)
    assert full.returncode == 0, full.stderr
    assert re.search(r"^  runner +NumPy$", full.stdout, re.M) and "20000 of 20000" in full.stdout
    ref = io.load(tmp_path / "full.h5")
    assert ref.complete and len(ref.ys) == 6668
    assert ref.config["model"] == TOY and ref.config["params"] == {"n": 4, "scale": 0.5}

    path = tmp_path / "killed.h5"
    proc = subprocess.Popen(
        isoflow_cmd(*model, *ARGS, "--out", str(path)), stderr=subprocess.DEVNULL, env=env,
        cwd=tmp_path,
    )  # fmt: skip
    kill_when(path, 300, proc)
    info = run_cli("info", str(path), env=env)
    assert info.returncode == 0 and f"not built in: resume with --model {TOY}" in info.stdout

    # the file alone imports nothing: the model must be named again, and match the record
    for args, pattern in [
        ([], rf"not built in.*--resume FILE --model {TOY}"),
        (["--model", "user_models:compiled_toy"], rf"written by model '{TOY}', not"),
        (["--model", TOY, "--param", "n=5"], r"parameter n = 5 differs from the run's n = 4"),
        (
            ["--model", TOY, "--param", "seed=1"],
            r"seed = 1 differs from the run's seed = 0 \(the model function's default\)",
        ),
        (["--model", TOY, "--dt", "0.02"], r"--dt cannot change it"),
        (["--model", TOY, "--out", "x.h5"], r"--out cannot change it"),
        (["--param", "n=4"], r"--param on --resume needs the model"),
    ]:
        res = run_cli("run", "--resume", str(path), *args, env=env)
        assert res.returncode == 1, (args, res.stderr)
        assert re.search(pattern, one_error_line(res.stderr)), (args, res.stderr)

    res = run_cli(
        "run",
        "--resume",
        str(path),
        "--model",
        TOY,
        "--param",
        "n=4",
        "--param",
        "seed=0",
        "--quiet",
        env=env,
    )  # fmt: skip  (seed: the default, not recorded)
    assert res.returncode == 0, res.stderr
    got = io.load(path)
    assert got.complete and got.run_info["status"] == 0
    assert got.ys.tobytes() == ref.ys.tobytes() and np.array_equal(got.ts, ref.ts)
    assert got.drifts == ref.drifts


def test_resume_of_a_changed_user_model_is_refused_unless_forced(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    write_user_model(tmp_path, "cli_fp")
    monkeypatch.syspath_prepend(str(tmp_path))
    full, part = tmp_path / "full.h5", tmp_path / "part.h5"
    with disk_before_each_write(full) as copies:
        code = cli.main(["run", "--model", "cli_fp:factory", "--dt", "0.01", "--n-steps", "60",
                         "--save-every", "2", "--chunk-rows", "2", "--flush-seconds", "1e-9",
                         "--out", str(full), "--quiet"])  # fmt: skip
    assert code == 0
    part.write_bytes(copies[len(copies) // 2])  # killed in the middle
    before = part.read_bytes()
    write_user_model(tmp_path, "cli_fp", factor="-2.0 * ")  # the user edits B
    env = {**user_env(), "PYTHONPATH": str(tmp_path)}
    res = run_cli("run", "--resume", str(part), "--model", "cli_fp:factory", env=env)
    line = one_error_line(res.stderr)
    assert res.returncode == 1 and "the model changed since the run started" in line
    assert "B differs at the probe state" in line and "--force" in line
    assert part.read_bytes() == before
    res = run_cli("run", "--resume", str(part), "--model", "cli_fp:factory", "--force", "--quiet",
                  env=env)  # fmt: skip
    assert res.returncode == 0, res.stderr
    assert io.load(part).complete


def test_user_compiled_model_from_toml(tmp_path: Path) -> None:
    (tmp_path / "run.toml").write_text(
        'model = "user_models:compiled_toy"\ndt = 0.05\nn_steps = 40\nsave_every = 4\n'
        'out = "c.h5"\n[params]\nn = 5\nseed = 2\n'
    )
    res = run_cli("run", "--config", "run.toml", "--quiet", cwd=tmp_path, env=user_env())
    assert res.returncode == 0, res.stderr
    assert re.search(r"^  runner +compiled", res.stdout, re.M)
    run = io.load(tmp_path / "c.h5")
    assert run.config["params"] == {"n": 5, "seed": 2} and len(run.ys) == 11
    assert run.drifts["casimir_drift"] < 1e-13


@pytest.mark.parametrize(
    ("args", "pattern"),
    [
        (["--model", "no_such_module_xyz:f"], r"cannot import 'no_such_module_xyz'"),
        (["--model", "user_models:missing"], r"has no attribute 'missing'"),
        (["--model", "user_models:not_a_model"], r"must return \(problem, initial_state\)"),
        (["--model", TOY, "--param", "colour=3"], r"unexpected keyword argument 'colour'"),
        (["--model", TOY, "--param", "n"], r"--param expects KEY=VALUE"),
        (["--model", "two:colons:here"], r"package.module:function"),
        (["rigid-body", "--model", "spin-chain"], r"two models given"),
    ],
)
def test_user_model_mistakes_are_one_line_errors(tmp_path: Path, args, pattern) -> None:
    res = run_cli_here("run", *args, "--dt", "0.1", "--n-steps", "2", "--out", "x.h5",
                       "--quiet", cwd=tmp_path)  # fmt: skip
    assert res.returncode == 1, res.stderr
    assert re.search(pattern, one_error_line(res.stderr)), res.stderr
    assert not (tmp_path / "x.h5").exists()


def test_entry_point_model_from_the_command_line(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    from isoflow import _compile_clock as notice

    ep = importlib.metadata.EntryPoint("toy", "user_models:TOY_SPEC", registry.ENTRY_POINT_GROUP)
    # isoflow's reader of the entry points, not importlib's: numba reads its own entry points
    # (with another API) when it first compiles in this process
    monkeypatch.setattr(registry._catalogue, "entry_points", lambda: {"toy": ep})
    out = str(tmp_path / "toy.h5")
    args = ["run", "toy", "--param", "n=3", "--dt", "0.1", "--n-steps", "30", "--quiet"]
    assert cli.main([*args, "--out", out]) == 0
    assert notice.SHOW is False  # announcing compilations ends with the command
    assert "run: toy (n = 3, scale = 0.5, seed = 0)" in capsys.readouterr().out
    assert io.load(out).config["params"] == {"n": 3, "scale": 0.5, "seed": 0}
    assert cli.main(["run", "toy", "--param", "n=99", "--dt", "0.1", "--n-steps", "3",
                     "--out", str(tmp_path / "big.h5")]) == 1  # fmt: skip
    assert "toy n must be <= 64" in capsys.readouterr().err
    assert cli.main(["run", "--resume", out]) == 1
    assert "--model toy" in capsys.readouterr().err
    assert cli.main(["run", "--resume", out, "--model", "toy", "--quiet"]) == 0
    assert cli.main(["list", "models"]) == 0
    assert "toy" in capsys.readouterr().out


#: Modules of a user with mistakes: name -> (source, the line the error names).
BROKEN_MODULES = {
    "um_syntax": ("import numpy as np\n\ndef factory(n=3)\n    return None\n", 3),
    "um_raises_on_import": ("import numpy as np\nscale = 1 / 0\n\ndef factory():\n    pass\n", 2),
    "um_missing_dependency": ("import no_such_dependency_xyz\n\ndef factory():\n    pass\n", 1),
    "um_memory": (
        "import numpy as np\n\n\ndef factory(n=4):\n    W = np.zeros((n, n))\n"
        "    return np.zeros((10**7, 10**7)), W\n",
        6,
    ),
    "um_key_error": ("def factory():\n    table = {}\n    return table['W0']\n", 3),
}


@pytest.mark.parametrize(
    ("module", "pattern"),
    [
        ("um_syntax", r"importing 'um_syntax' raised SyntaxError at {file}:{line}: expected ':'$"),
        ("um_raises_on_import",
         r"importing 'um_raises_on_import' raised ZeroDivisionError at {file}:{line}: division"),
        ("um_missing_dependency", r"importing 'um_missing_dependency' raised "
         r"ModuleNotFoundError at {file}:{line}: No module named 'no_such_dependency_xyz'$"),
        ("um_memory", r"the factory raised MemoryError at {file}:{line}: Unable to allocate"),
        ("um_key_error", r"the factory raised KeyError at {file}:{line}: 'W0'$"),
    ],
)  # fmt: skip
def test_errors_in_the_users_code_are_one_line_with_the_place(
    module: str, pattern: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
) -> None:  # fmt: skip
    source, line = BROKEN_MODULES[module]
    (tmp_path / f"{module}.py").write_text(source)
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.delenv("ISOFLOW_DEBUG", raising=False)
    args = ["run", "--model", f"{module}:factory", "--dt", "0.1", "--n-steps", "2", "--out",
            str(tmp_path / "x.h5"), "--quiet"]  # fmt: skip
    assert cli.main(args) == 1
    err = one_error_line(capsys.readouterr().err)
    expected = pattern.format(file=re.escape(str(tmp_path / f"{module}.py")), line=line)
    assert re.search(rf"^isoflow: error: model '{module}:factory': " + expected, err), err


@pytest.mark.parametrize(
    ("args", "pattern"),
    [
        (["--model", TOY, "--param", "n=[1,"],
         r"--param n: '\[1,' is not a TOML value \(.*\); write a list as \[1, 2\]"),
        (["--model", TOY, "--param", "scale={a = "], r"--param scale: '\{a =' is not a TOML"),
        (["--model", TOY, "--param", 'seed="1'], r"--param seed: '\"1' is not a TOML value"),
        (["spin-lattice", "--shape", "[16,"],
         r"spin-lattice shape must be a list of 2 int values written like 16,16, got '\[16,'"),
        (["spin-lattice", "--field", "1,,2"], r"field must be a list of 3 float values written "
         r"like 0,0,0, got '1,,2'"),
    ],
)  # fmt: skip
def test_malformed_list_values_are_refused(
    args: list[str], pattern: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert cli.main(["run", *args, "--dt", "0.1", "--n-steps", "2", "--out",
                     str(tmp_path / "x.h5"), "--quiet"]) == 1  # fmt: skip
    assert re.search(pattern, one_error_line(capsys.readouterr().err))
    assert not (tmp_path / "x.h5").exists()
