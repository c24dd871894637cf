"""``isoflow demo``: the paper's so(n) rigid body with IsoMP, printing invariant drifts."""

from __future__ import annotations

import argparse
import time
from typing import Any

from .. import registry
from .._version import __version__
from ._common import (
    add_thread_options,
    anderson_memory,
    announce_compiles,
    positive_float,
    positive_int,
    progress,
)

__all__ = ["add_parser", "handle"]


def add_parser(sub: Any) -> None:
    """Declare ``isoflow demo`` on the subparsers ``sub``."""
    demo = sub.add_parser(
        "demo",
        help="integrate the paper's so(n) rigid body and print invariant drifts",
        description=(
            "Generalized rigid body on so(n) (paper, Sec. 3.1, with the symmetrized inertia), "
            "integrated by IsoMP. Prints the drift of the Casimirs (eigenvalues), of the "
            "Hamiltonian and of the distance to so(n)."
        ),
    )
    demo.add_argument("--n", type=positive_int, default=10, help="matrix size (default 10)")
    demo.add_argument("--dt", type=positive_float, default=0.1, help="step size (default 0.1)")
    demo.add_argument("--t1", type=positive_float, default=100.0, help="final time (default 100)")
    demo.add_argument(
        "--solver",
        choices=tuple(registry.SOLVERS),
        default="fixed-point",
        help="nonlinear solver for the stage (default fixed-point)",
    )
    demo.add_argument(
        "--anderson",
        type=anderson_memory,
        default=0,
        metavar="M",
        help="Anderson memory (0: plain)",
    )
    demo.add_argument("--quiet", action="store_true", help="no progress bar")
    add_thread_options(demo)
    demo.set_defaults(handler=handle, computes=True)


def handle(args: argparse.Namespace) -> int:
    """Run the demo; exit status 0 when the run succeeded."""
    from .._solve import solve

    config = {
        "model": "rigid-body",
        "params": {"n": args.n},
        "method": "isomp",
        "solver": args.solver,
        "anderson": args.anderson,
        "dt": args.dt,
        "t1": args.t1,
        "save_every": max(1, round(1.0 / args.dt)),
    }
    problem, W0, method, kwargs = registry.build(config)
    announce_compiles()
    # one step first, so that loading the compiled kernels is not counted as stepping
    solve(problem, method, W0, dt=args.dt, n_steps=1, progress=False)
    start = time.perf_counter()
    sol = solve(problem, method, W0, **kwargs, progress=progress(args))
    wall = time.perf_counter() - start
    d = sol.diagnostics.summary() if sol.diagnostics is not None else {}
    solver = args.solver + (f", Anderson {args.anderson}" if args.anderson else "")
    rows = [
        ("steps", f"{sol.stats.n_steps}"),
        (
            "wall time",
            f"{wall:.3f} s ({1e6 * wall / max(sol.stats.n_steps, 1):.1f} us/step, warm)",
        ),
        (
            "iterations per step",
            f"mean {sol.stats.iterations_mean:.2f}, max {sol.stats.iterations_max}",
        ),
        ("Casimir drift", f"{d['casimir_drift']:.2e}  (eigenvalues, relative to ||W0||)"),
        (
            "Hamiltonian drift",
            f"{d['hamiltonian_relative_drift']:.2e}  (relative; bounded, O(h^2))",
        ),
        (f"distance to so({args.n})", f"{d['max_distance']:.2e}"),
        ("status", sol.message),
    ]
    lines = [
        f"isoflow {__version__} demo: generalized rigid body on so({args.n}), IsoMP "
        f"({solver}), h = {args.dt:g}, T = {args.t1:g}",
        *(f"  {name:<22} {value}" for name, value in rows),
    ]
    print("\n".join(lines))
    return 0 if sol.success else 1
