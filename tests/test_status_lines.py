"""Status lines of long runs: the step, the speed and the projected end, on stderr."""

from __future__ import annotations

import re
from datetime import UTC, datetime, timedelta
from pathlib import Path

import pytest

import isoflow as iso
from isoflow._status_lines import duration_text, status_line

LINE = re.compile(
    r"^isoflow: step (\d+) of (\d+) \((\d+\.\d) %\), t = (\S+), (\S+) steps/s, "
    r"ends about .+ \(in .+\)$"
)


def test_a_status_line_projects_the_end_from_the_speed() -> None:
    now = datetime(2026, 11, 26, 12, 0, tzinfo=UTC)
    line = status_line(1200, 50000, 12.0, 3.2, now)
    end = now + timedelta(seconds=(50000 - 1200) / 3.2)  # 15250 s: 4 h 14 min later
    assert end.strftime("%H:%M") == "16:14"
    assert line == (
        "isoflow: step 1200 of 50000 (2.4 %), t = 12, 3.2 steps/s, "
        "ends about Thu 26 Nov 16:14 UTC (in 4 h 14 min)"
    )


def test_a_status_line_without_a_speed_says_where_the_run_stands() -> None:
    now = datetime(2026, 11, 26, 12, 0, tzinfo=UTC)
    assert status_line(0, 10, 0.0, None, now) == "isoflow: step 0 of 10 (0.0 %), t = 0"


@pytest.mark.parametrize(
    ("seconds", "text"),
    [
        (0.4, "0 s"),
        (42, "42 s"),
        (600, "10 min"),
        (15250, "4 h 14 min"),
        (3 * 86400 + 7300, "3 d 2 h"),
    ],
)
def test_durations_read_at_a_glance(seconds: float, text: str) -> None:
    assert duration_text(seconds) == text


def test_solve_writes_status_lines_with_the_steps_it_has_done(
    capsys: pytest.CaptureFixture[str],
) -> None:
    problem, y0 = iso.models.rigid_body(3)
    n = 400
    sol = iso.solve(problem, iso.IsoMP(), y0, dt=0.01, n_steps=n, progress=False,
                    status_every=1e-9)  # fmt: skip
    assert sol.success
    lines = capsys.readouterr().err.splitlines()
    parsed = [LINE.match(s) for s in lines]
    assert lines and all(parsed), lines
    steps = [int(m.group(1)) for m in parsed if m]
    # the first chunk takes 1 step (not timed: it may compile), the second 4: a line at step 5
    assert steps[0] == 5 and steps == sorted(set(steps)) and steps[-1] < n, steps
    for m in parsed:
        assert m is not None and int(m.group(2)) == n
        assert float(m.group(4)) == pytest.approx(0.01 * int(m.group(1)), rel=1e-12, abs=1e-15)
        assert float(m.group(5)) > 0


def test_without_status_every_a_run_writes_no_status_line(
    capsys: pytest.CaptureFixture[str],
) -> None:
    problem, y0 = iso.models.rigid_body(3)
    iso.solve(problem, iso.IsoMP(), y0, dt=0.01, n_steps=50, progress=False)
    assert "steps/s" not in capsys.readouterr().err


@pytest.mark.parametrize("bad", [0, -1.0, float("nan"), float("inf"), True, "60"])
def test_a_bad_status_interval_is_refused(bad: object) -> None:
    problem, y0 = iso.models.rigid_body(3)
    with pytest.raises(iso.ParameterError, match="status_every must be a positive number"):
        iso.solve(problem, iso.IsoMP(), y0, dt=0.01, n_steps=5, status_every=bad)  # type: ignore[arg-type]


def test_isoflow_run_and_resume_write_status_lines_and_quiet_silences_them(
    tmp_path: Path,
) -> None:
    from isoflow import io
    from isoflow.cli import main

    out = tmp_path / "run.h5"
    args = ["run", "rigid-body", "--dt", "0.01", "--n-steps", "300", "--out", str(out)]
    with pytest.MonkeyPatch.context() as mp:
        import sys
        from io import StringIO

        err = StringIO()
        mp.setattr(sys, "stderr", err)
        assert main([*args, "--status-every", "1e-9"]) == 0
        lines = [s for s in err.getvalue().splitlines() if s.startswith("isoflow: step")]
        assert lines and all(LINE.match(s) for s in lines), err.getvalue()[-2000:]

        err = StringIO()
        mp.setattr(sys, "stderr", err)
        assert main([*args, "--force", "--status-every", "1e-9", "--quiet"]) == 0
        assert "steps/s" not in err.getvalue()
    assert io.load(out).complete
