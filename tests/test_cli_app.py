"""The command line: registry names everywhere, configuration mistakes, plot, list, bench."""

from __future__ import annotations

import json
import re
import sys
from pathlib import Path

import pytest

from cli_helpers import one_error_line, run_cli, run_cli_here
from isoflow import cli, registry

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def toml_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    d = tmp_path_factory.mktemp("toml")
    head = 'model = "rigid-body"\ndt = 0.1\nn_steps = 5\nout = "x.h5"\n'
    cases = {
        "params3": head + "params = 3\n",
        "out7": 'model = "rigid-body"\ndt = 0.1\nn_steps = 5\nout = 7\n',
        "dtstring": 'model = "rigid-body"\ndt = "0.1"\nn_steps = 5\nout = "x.h5"\n',
        "rk4newton": head + 'method = "rk4"\nsolver = "newton"\n',
        "huge": head + "[params]\nn = 100000\n",
        "datetime": head + "[params]\nn = 1979-05-27\n",
        "anderson": head + 'solver = "newton-krylov"\nanderson = 3\n',
    }
    for name, text in cases.items():
        (d / f"{name}.toml").write_text(text)
    return d


@pytest.mark.parametrize(
    ("name", "pattern"),
    [
        ("params3", r"params must be a table of model parameters, got 3"),
        ("out7", r"out must be a file name \(a string\), got 7"),
        ("dtstring", r"dt must be a number, got '0.1'"),
        ("rk4newton", r"method 'rk4' is explicit: it takes no nonlinear solver"),
        ("huge", r"rigid-body n must be <= 2048, got 100000"),
        ("datetime", r"rigid-body n must be an integer"),
        ("anderson", r"anderson = 3 is an option of the fixed-point solver"),
    ],
)
def test_toml_mistakes_are_one_line_errors(toml_dir: Path, name: str, pattern: str) -> None:
    res = run_cli_here("run", "--config", f"{name}.toml", "--quiet", cwd=toml_dir)
    assert res.returncode == 1, res.stderr
    assert re.search(pattern, one_error_line(res.stderr)), res.stderr
    assert not (toml_dir / "x.h5").exists()


def test_run_with_anderson_and_an_old_spelling(tmp_path: Path) -> None:
    res = run_cli("run", "heisenberg-chain", "--N", "8", "--dt", "0.1", "--n-steps", "20",
                  "--anderson", "2", "--out", "a.h5", "--quiet", cwd=tmp_path)  # fmt: skip
    assert res.returncode == 0, res.stderr
    from isoflow import io

    run = io.load(tmp_path / "a.h5")
    assert run.config["model"] == "spin-chain" and run.config["anderson"] == 2


def test_plot_does_not_replace_files_silently(tmp_path: Path) -> None:
    res = run_cli("run", "rigid-body", "--n", "3", "--dt", "0.1", "--n-steps", "10", "--out",
                  "r.h5", "--quiet", cwd=tmp_path)  # fmt: skip
    assert res.returncode == 0, res.stderr
    png = tmp_path / "r.png"
    png.write_bytes(b"mine")
    res = run_cli("plot", "r.h5", "--out", "r.png", cwd=tmp_path)
    assert res.returncode == 1 and "r.png exists (use --force" in one_error_line(res.stderr)
    assert png.read_bytes() == b"mine"
    res = run_cli("plot", "r.h5", "--out", "r.png", "--force", cwd=tmp_path)
    assert res.returncode == 0, res.stderr
    assert png.read_bytes()[:4] == b"\x89PNG"
    (tmp_path / "d.png").mkdir()
    res = run_cli("plot", "r.h5", "--out", "d.png", "--force", cwd=tmp_path)
    assert res.returncode == 1 and "not a regular file" in one_error_line(res.stderr)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["d.png", "r.h5", "r.png"]  # no temp


def test_list_shows_the_registry(capsys: pytest.CaptureFixture[str]) -> None:
    assert cli.main(["list"]) == 0
    out = capsys.readouterr().out
    for names in (registry.MODELS, registry.METHODS, registry.SOLVERS, registry.EXPERIMENTS):
        for name in names:
            assert re.search(rf"^  {re.escape(name)}\s", out, re.M), name
    assert "rigid-body" in out and "n (int, default 10)" in out and "at most 2048" in out


def test_list_shows_parameters_as_they_are_typed(capsys: pytest.CaptureFixture[str]) -> None:
    assert cli.main(["list"]) == 0
    out = capsys.readouterr().out
    assert "shape (2-vector of int, default 16,16): lattice size L1, L2 [at most 3000]" in out
    assert "field (3-vector of float, default 0,0,0): Zeeman field h" in out
    assert "N (int, default 100): number of spins [at most 10000000]" in out
    assert "initial (str, default curve):" in out and "scale (float): norm scale" in out
    assert "RK, 1 stage, order 2" in out and "RK, 2 stages, order 4" in out
    assert "default None" not in out and "[16, 16]" not in out and "1e+07" not in out


def test_run_help_says_which_model_takes_which_parameter() -> None:
    run = cli.build_parser()._subparsers._group_actions[0].choices["run"]  # type: ignore[union-attr]
    group = next(g for g in run._action_groups if g.title == "model parameters")
    helps = {a.option_strings[0]: a.help for a in group._group_actions}
    assert helps["--n"] == (
        "rigid-body: matrix size of so(n) (default 10); brockett: matrix size of herm(n) "
        "(default 10); toda: number of particles (default 12)"
    )
    assert helps["--shape"] == "spin-lattice: lattice size L1, L2 (default 16,16)"
    flags = {f for spec in registry.MODELS.values() for f in spec.params or {}}
    assert len(helps) == len(flags) + 1 and "--param" in helps  # every model flag is here


@pytest.mark.parametrize("command", ["info", "plot"])
def test_info_and_plot_help_describe_the_command(command: str) -> None:
    parser = cli.build_parser()._subparsers._group_actions[0].choices[command]  # type: ignore[union-attr]
    assert parser.description and len(parser.description) > 100


def _columns(lines: list[str]) -> set[int]:
    """Where the values start in ``  name  value`` lines."""
    return {len(ln) - len(ln[2:].split("  ", 1)[1].lstrip()) for ln in lines}


def test_info_aligns_its_rows_and_suggests_resuming_only_a_resumable_file(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = str(tmp_path / "toy.h5")
    args = ["run", "--model", "user_models:toy_rigid_body", "--param", "n=3", "--dt", "0.1",
            "--n-steps", "20", "--quiet", "--out", out]  # fmt: skip
    assert cli.main(args) == 0
    summary = capsys.readouterr().out.splitlines()
    assert len(_columns(summary[1:])) == 1, summary
    assert cli.main(["info", out]) == 0
    shown = capsys.readouterr().out.splitlines()
    assert any(ln.startswith("  hamiltonian_relative_drift  ") for ln in shown)
    assert len(_columns(shown[1:])) == 1, shown
    assert "  model" in shown[1] and shown[1].split()[1:4] == [
        "user_models:toy_rigid_body", "(not", "built"
    ]  # fmt: skip
    assert "resume with" not in "\n".join(shown) and re.search(r"resumable +no$", shown[6])


def test_plot_has_no_empty_panel_without_a_hamiltonian(tmp_path: Path) -> None:
    from isoflow import io, plotting

    out = str(tmp_path / "c.h5")
    args = ["run", "--model", "user_models:compiled_toy", "--param", "n=4", "--dt", "0.05",
            "--n-steps", "20", "--quiet", "--out", out]  # fmt: skip
    assert cli.main(args) == 0
    run = io.load(out)
    assert "hamiltonian" not in run.series and "lyapunov" not in run.series
    fig = plotting.plot_run(run)
    titles = [ax.get_title() for ax in fig.axes]
    assert len(fig.axes) == 3 and all(titles) and not any("Hamiltonian" in t for t in titles)
    toy = str(tmp_path / "toy.h5")
    assert cli.main(["run", "--model", "user_models:toy_rigid_body", "--dt", "0.1",
                     "--n-steps", "20", "--quiet", "--out", toy]) == 0  # fmt: skip
    titles = [ax.get_title() for ax in plotting.plot_run(io.load(toy)).axes]
    assert len(titles) == 4 and "Hamiltonian variation" in titles


def test_plot_of_an_ensemble_draws_one_member_named_in_the_title(tmp_path: Path) -> None:
    """Each curve is that member's (its Casimirs C_1..C_k, not the members' flattened); a
    failed ensemble says so in the title; a member out of range is a one-line error."""
    import numpy as np

    from helpers import failed_ensemble_file
    from isoflow import io, plotting

    path = failed_ensemble_file(tmp_path / "ens.h5")  # member 1 fails at its first step
    run = io.load(path)
    fig = plotting.plot_run(run, member=2)
    assert "member 2 of 3" in fig._suptitle.get_text() and "failed" in fig._suptitle.get_text()
    casimirs = next(ax for ax in fig.axes if ax.get_title().startswith("Casimir"))
    assert casimirs.get_legend_handles_labels()[1] == [f"$C_{{{j}}}$" for j in range(1, 5)]
    C = np.real(run.series["casimirs"])[:, 2]
    drawn = np.stack([line.get_ydata() for line in casimirs.lines], axis=1)
    scale = np.max(np.abs(C - C[:1])) / np.max(np.abs(drawn))  # the axis' power of ten
    assert np.allclose(drawn * scale, C - C[:1], rtol=1e-6, atol=1e-18)
    out = tmp_path / "m.png"
    assert cli.main(["plot", str(path), "--out", str(out), "--member", "0"]) == 0
    bad = run_cli("plot", str(path), "--out", str(tmp_path / "x.png"), "--member", "3")
    assert bad.returncode == 1 and "not a member of this ensemble of shape (3,)" in (
        one_error_line(bad.stderr)
    )


def test_plot_names_the_fields_of_a_pair(tmp_path: Path) -> None:
    """The heavy top's state is the pair (Gamma, M): its components are named so, not as two
    particles w_0, w_1 (the file records the fields' names)."""
    import isoflow as iso
    from isoflow import io, plotting

    prob, y0 = iso.models.heavy_top()
    path = tmp_path / "top.h5"
    iso.solve(prob, iso.IsoMP(), y0, dt=0.01, n_steps=30, writer=io.HDF5Writer(path),
              progress=False)  # fmt: skip
    run = io.load(path)
    assert run.meta["fields"] == ["Gamma", "M"]
    fig = plotting.plot_run(run)
    states = next(ax for ax in fig.axes if ax.get_title().startswith("state"))
    labels = states.get_legend_handles_labels()[1]
    assert labels and all(label.split(".")[0] in ("Gamma", "M") for label in labels)


def test_parser_names_come_from_the_registry() -> None:
    parser = cli.build_parser()
    sub = next(a for a in parser._actions if a.dest == "command").choices
    demo_solver = next(a for a in sub["demo"]._actions if a.dest == "solver")
    assert tuple(demo_solver.choices) == tuple(registry.SOLVERS)
    rep = next(a for a in sub["reproduce"]._actions if a.dest == "experiment")
    assert tuple(rep.choices) == ("all", *registry.EXPERIMENTS)


@pytest.mark.parametrize(
    ("args", "pattern"),
    [
        (["--only", "x"], r"not a comma-separated list of benchmark numbers: 'x'"),
        (["--only", "98"], r"no benchmark 98 \(benchmarks: 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12"),
        (["--only", "1,99"], r"no benchmark 99"),
    ],
)
def test_bench_mistakes_are_one_line_errors(args: list[str], pattern: str) -> None:
    res = run_cli("bench", *args)  # the suite runs in a subprocess of its own
    assert res.returncode == 2, res.stderr
    assert re.search(pattern, one_error_line(res.stderr)), res.stderr


def test_bench_without_a_source_tree(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    from isoflow.cli import _bench

    monkeypatch.setattr(_bench, "source_tree", lambda: None)
    assert cli.main(["bench", "--quick"]) == 1
    err = capsys.readouterr().err
    assert "isoflow: error: the benchmarks live in the source repository" in err
    assert "pip install -e ." in err


def test_bench_runs_a_benchmark_of_the_suite(tmp_path: Path) -> None:
    """Benchmark 6 counts iterations (no timing): the suite runs on the current API."""
    out = tmp_path / "bench"
    res = run_cli("bench", "--quick", "--only", "6", "--out", str(out))
    assert res.returncode == 0, res.stderr
    report = json.loads((out / "benchmarks.json").read_text())
    rows = report["results"]
    assert {r["id"] for r in rows} == {6} and len(rows) == 4
    rigid = [r for r in rows if "rigid" in r["name"]]
    assert all(r["iterations_default"] < r["iterations_paper_X0_eq_W"] for r in rigid)
    assert all(r["max_difference_of_answers"] <= 1e-13 for r in rigid)
    assert "| 6 |" in (out / "benchmarks.md").read_text()


def test_every_benchmark_is_registered_once() -> None:
    sys.path.insert(0, str(ROOT / "benchmarks"))
    try:
        import suite

        benchmarks = suite.load()
    finally:
        sys.path.remove(str(ROOT / "benchmarks"))
    ids = list(benchmarks)
    assert ids == sorted(set(ids)) and set(range(1, 15)) <= set(ids), ids  # later issues add more
    files = sorted(p.stem for p in (ROOT / "benchmarks").glob("bench_*.py"))
    assert sorted(b.source for b in benchmarks.values() if b.source != "design") == files
    for k, b in benchmarks.items():
        assert b.title and not b.title.startswith("benchmark "), (k, b.title)
        assert b.source.startswith(f"bench_{k}_") or b.source == "design", (k, b.source)


def test_a_closed_pipe_is_not_an_error() -> None:
    import subprocess

    from cli_helpers import isoflow_cmd

    proc = subprocess.Popen(isoflow_cmd("list"), stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    assert proc.stdout is not None and proc.stderr is not None
    proc.stdout.close()  # the reader is gone before the command writes (`isoflow list | true`)
    err = proc.stderr.read().decode()
    proc.wait(timeout=600)
    assert "error" not in err and "Traceback" not in err, err
