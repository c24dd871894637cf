"""The ``isoflow`` command through its real entry point (subprocess)."""

from __future__ import annotations

import re

import pytest

from cli_helpers import run_cli as _run


def test_demo_reports_rounding_level_casimir_drift() -> None:
    out = _run("demo", "--t1", "20", "--quiet")
    assert out.returncode == 0, out.stderr
    drift = float(re.search(r"Casimir drift\s+(\S+)", out.stdout).group(1))
    dist = float(re.search(r"distance to so\(10\)\s+(\S+)", out.stdout).group(1))
    assert drift <= 1e-13 and dist == 0.0
    assert "200 steps" in out.stdout


@pytest.mark.parametrize(
    ("args", "code", "pattern"),
    [
        (["demo", "--dt", "-1"], 2, r"--dt: must be positive"),
        (["demo", "--n", "zero"], 2, r"--n: not an integer"),
        (["demo", "--dt", "0.3"], 1, r"isoflow: error: .*not a whole number of steps"),
        (["frobnicate"], 2, r"invalid choice"),
    ],
)
def test_user_mistakes_give_one_line_errors(args: list[str], code: int, pattern: str) -> None:
    out = _run(*args)
    assert out.returncode == code
    assert re.search(pattern, out.stderr)
    assert "Traceback" not in out.stderr


def test_version() -> None:
    out = _run("--version")
    assert out.returncode == 0 and out.stdout.startswith("isoflow ")


def test_bench_is_wired_to_the_benchmark_suite() -> None:
    out = _run("bench", "--help")
    assert out.returncode == 0
    assert out.stdout.startswith("usage: isoflow bench")
