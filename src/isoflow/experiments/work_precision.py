"""Work–precision: where IsoMP, its compositions, IsoSyRK, RK4 and DOP853 each win.

Two problems of the paper at ``T = 10`` (the so(10) rigid body and the spin chain with
``N = 100``): the relative error at ``T`` against the wall time and against the number of
evaluations of ``B``, for IsoMP, the five symmetric compositions of IsoMP, IsoSyRK with 2 and
3 stages, the classical RK4 (fixed steps swept) and scipy's DOP853 (tolerances swept). Then a
long run (``T = 10^4``) on the rigid body: the Casimir and energy errors against time for the
cheapest structure-preserving method at an error of ``1e-10`` and for DOP853 at the same
accuracy. The reference is DOP853 at ``rtol = atol = 1e-14``, checked against the 8th-order
composition at a small step.
"""

from __future__ import annotations

import time
from typing import TYPE_CHECKING, Any

import numpy as np

from .. import models
from .._figures import new_figure
from .._solve import solve
from ..methods import RK4, Composition, IsoMP, IsoSyRK, Method
from ..nonlinear import FixedPoint
from ..reference import dop853
from ._base import Experiment, ExperimentResult, check, header

if TYPE_CHECKING:
    from matplotlib.figure import Figure

__all__ = ["WorkPrecision", "work_precision"]

#: The compositions of the experiment, by scheme name.
SCHEMES = ("triple-jump-4", "suzuki-4", "yoshida-6", "kahan-li-6", "kahan-li-8")


def _families(quick: bool) -> dict[str, tuple[Method, list[int]]]:
    """method label -> (method, numbers of steps over ``T``)."""

    def steps(lo: int, hi: int, k: int) -> list[int]:
        return sorted({round(float(v)) for v in np.geomspace(lo, hi, k)})

    k = 4 if quick else 7
    out: dict[str, tuple[Method, list[int]]] = {
        "IsoMP": (IsoMP(), steps(100, 3_000 if quick else 300_000, k)),
    }
    for scheme in SCHEMES:
        hi = {"triple-jump-4": 20_000, "suzuki-4": 8_000}.get(scheme, 2_000)
        out[f"IsoMP o {scheme}"] = (
            Composition(IsoMP(), scheme),
            steps(10, hi // (10 if quick else 1), k),
        )
    out["IsoSyRK(2)"] = (IsoSyRK(2), steps(10, 100 if quick else 1_000, k))
    out["IsoSyRK(3)"] = (IsoSyRK(3), steps(10, 60 if quick else 400, k))
    out["RK4"] = (RK4(), steps(50, 500 if quick else 5_000, k))
    return out


def _positive(x: Any) -> Any:
    """``x`` with zeros (exact agreement at a point, t = 0) left out of log axes."""
    x = np.asarray(x, dtype=float)
    return np.where(x > 0, x, np.nan)


def _relative_error(y: Any, ref: Any) -> float:
    return float(np.linalg.norm(y - ref) / np.linalg.norm(ref))


def _sweep(problem: Any, y0: Any, T: float, ref: Any, quick: bool) -> dict[str, dict[str, list]]:
    """Per method: the step counts (or tolerances), errors, wall times and ``B`` evaluations."""
    out: dict[str, dict[str, list]] = {}
    for label, (method, counts) in _families(quick).items():
        solve(problem, method, y0, dt=T / counts[0], n_steps=2, progress=False, throw=False)
        rec: dict[str, list] = {"steps": [], "error": [], "seconds": [], "B_evaluations": []}
        for n in counts:
            start = time.perf_counter()
            sol = solve(problem, method, y0, dt=T / n, n_steps=n, save_every=n,
                        diagnostics=False, progress=False, throw=False)  # fmt: skip
            wall = time.perf_counter() - start
            if not sol.success:
                continue  # the solve does not converge at this step: no point
            rec["steps"].append(n)
            rec["error"].append(_relative_error(sol.ys[-1], ref))
            rec["seconds"].append(wall)
            rec["B_evaluations"].append(int(sol.stats.n_B_evaluations))
        out[label] = rec
    rec = {"tolerance": [], "error": [], "seconds": [], "B_evaluations": []}
    for tol in np.geomspace(1e-4, 1e-12, 4 if quick else 9):
        start = time.perf_counter()
        y, nfev = dop853(problem, y0, [T], rtol=float(tol), atol=float(tol))
        rec["seconds"].append(time.perf_counter() - start)
        rec["tolerance"].append(float(tol))
        rec["error"].append(_relative_error(y[0], ref))
        rec["B_evaluations"].append(nfev)
    out["DOP853"] = rec
    return out


def _at_error(rec: dict[str, list], target: float, key: str = "seconds") -> float:
    """``key`` at the relative error ``target``, interpolated log-log between the measured
    points that bracket it (``nan`` when the method does not reach it)."""
    e = np.asarray(rec["error"], dtype=float)
    v = np.asarray(rec[key], dtype=float)
    ok = (e > 0) & np.isfinite(e)
    e, v = e[ok], v[ok]
    best = np.nan
    for i in range(len(e)):
        for j in range(len(e)):
            if e[i] >= target >= e[j] and e[i] != e[j]:
                w = np.log(target / e[i]) / np.log(e[j] / e[i])
                val = float(np.exp(np.log(v[i]) + w * (np.log(v[j]) - np.log(v[i]))))
                best = val if not np.isfinite(best) else min(best, val)
    return best


class WorkPrecision(Experiment):
    """Error against cost for every method, and a long run (issue: higher order)."""

    name = "work-precision"
    description = (
        "error at T = 10 against wall time and B evaluations (so(10) rigid body, spin chain "
        "N = 100) for IsoMP, compositions, IsoSyRK, RK4 and DOP853; Casimirs over T = 10^4"
    )

    def run(
        self,
        *,
        T: float = 10.0,
        T_long: float | None = None,
        target: float | None = None,
        quick: bool = False,
        progress: bool | None = None,
    ) -> ExperimentResult:
        """Run the sweeps and the long run (``quick``: fewer and coarser points, ``T_long =
        100`` and the comparisons at error ``1e-6``; else ``T_long = 10^4`` and ``1e-10``).

        The JSON separates the ``checks`` (claims that must hold: the reference agrees with
        the 8th-order composition, the long run keeps the Casimirs at rounding) from the
        ``targets`` (the speed comparisons at the target error, met or not on this machine).

        Returns
        -------
        ExperimentResult
            ``data``: per problem, per method, the lists of the sweep; ``long``: times and the
            Casimir and energy errors of the long runs.
        """
        start = time.perf_counter()
        T_long = (100.0 if quick else 1e4) if T_long is None else T_long
        target = (1e-6 if quick else 1e-10) if target is None else target
        problems = {
            "rigid body so(10)": models.rigid_body(10),
            "spin chain N = 100": models.heisenberg_chain(100),
        }
        sweeps: dict[str, Any] = {}
        references: dict[str, float] = {}
        for pname, (problem, y0) in problems.items():
            ref = dop853(problem, y0, [T], rtol=2.5e-14, atol=2.5e-14)[0][0]
            check_ref = solve(
                problem, Composition(IsoMP(solver=FixedPoint(rtol=1e-16)), "kahan-li-8"), y0,
                dt=T / 400, n_steps=400, save_every=400, progress=False,
            ).ys[-1]  # fmt: skip
            references[pname] = _relative_error(check_ref, ref)
            sweeps[pname] = _sweep(problem, y0, T, ref, quick)
        rb = sweeps["rigid body so(10)"]
        at = {label: _at_error(rec, target) for label, rec in rb.items()}
        preserving = {k: v for k, v in at.items() if k.startswith(("IsoMP o", "IsoSyRK"))}
        reached = [k for k in preserving if np.isfinite(preserving[k])]
        best = min(reached, key=lambda k: preserving[k]) if reached else "IsoMP o kahan-li-8"
        speed_vs_isomp = at["IsoMP"] / at[best] if np.isfinite(at[best]) else np.nan
        speed_vs_dop = at["DOP853"] / at[best] if np.isfinite(at[best]) else np.nan
        long = self._long_run(problems["rigid body so(10)"], best, rb, target, T_long, progress)
        summary = header(self.name, {"T": T, "T_long": T_long, "target_error": target}, quick)
        summary |= {
            "reference_check": references,
            "seconds_at_target_error": {k: (v if np.isfinite(v) else None) for k, v in at.items()},
            "B_evaluations_at_target_error": {
                k: _at_error(rec, target, "B_evaluations") for k, rec in rb.items()
            },
            "best_structure_preserving": best,
            "long_run": {k: v for k, v in long.items() if not isinstance(v, np.ndarray)},
            "targets": {
                "faster_than_isomp": check(
                    speed_vs_isomp,
                    5.0,
                    f"{best} at least 5x faster than IsoMP at error {target:g} (rigid body)",
                    below=False,
                ),
                "not_slower_than_dop853": check(
                    speed_vs_dop,
                    1.0,
                    f"{best} no slower than DOP853 at error {target:g}",
                    below=False,
                ),
            },
            "checks": {
                "reference": check(
                    max(references.values()),
                    1e-12,
                    "the DOP853 reference agrees with the 8th-order composition at a small step",
                ),
                "long_run_casimirs": check(
                    long["casimir_drift"],
                    1e-13,
                    f"{best}: Casimir drift over T = {T_long:g} at rounding (relative)",
                ),
                "long_run_dop853_drifts": check(
                    long["casimir_drift_dop853"],
                    long["casimir_drift"],
                    "DOP853's Casimir drift at the same accuracy is larger",
                    below=False,
                ),
            },
        }
        data = {"sweeps": sweeps, "long": long}
        return self._result(data, summary, start)

    def _long_run(
        self, rb: tuple[Any, Any], best: str, sweep: dict[str, Any], target: float,
        T_long: float, progress: bool | None,
    ) -> dict[str, Any]:  # fmt: skip
        """The best structure-preserving method and DOP853 at the accuracy ``target``
        (their step count / tolerance interpolated from the sweep) over ``T_long``."""
        problem, y0 = rb
        method = _families(False)[best][0]
        steps = _at_error(sweep[best], target, "steps")
        n_per_10 = int(np.ceil(steps)) if np.isfinite(steps) else 100
        h = 10.0 / n_per_10
        n = round(T_long / h)
        save = max(1, n // 400)
        start = time.perf_counter()
        sol = solve(problem, method, y0, dt=h, n_steps=n, save_every=save, progress=progress)
        wall = time.perf_counter() - start
        d = sol.diagnostics
        assert d is not None and d.hamiltonian is not None
        C = np.real(d.casimirs)
        scale = problem.algebra.casimir_scale(y0)
        tol = _at_error(sweep["DOP853"], target, "tolerance")
        tol = float(tol) if np.isfinite(tol) else 1e-10
        ts = sol.ts
        start = time.perf_counter()
        Y, nfev = dop853(problem, y0, ts, rtol=tol, atol=tol)
        wall_dop = time.perf_counter() - start
        C_dop = problem.algebra.casimirs(Y)
        H_dop = problem.hamiltonian(Y)
        return {
            "ts": ts,
            "casimir_error": np.max(np.abs(C - C[:1]) / scale, axis=-1),
            "energy_error": np.abs(d.hamiltonian - d.hamiltonian[0]) / abs(d.hamiltonian[0]),
            "casimir_error_dop853": np.max(np.abs(C_dop - C_dop[:1]) / scale, axis=-1),
            "energy_error_dop853": np.abs(H_dop - H_dop[0]) / abs(H_dop[0]),
            "method": best,
            "h": h,
            "dop853_tolerance": tol,
            "casimir_drift": float(np.max(d.casimir_drift)),
            "casimir_drift_dop853": float(np.max(np.abs(C_dop - C_dop[:1]) / scale)),
            "energy_drift": float(np.max(np.asarray(d.hamiltonian_relative_drift))),
            "energy_drift_dop853": float(np.max(np.abs(H_dop - H_dop[0]) / abs(H_dop[0]))),
            "seconds": wall,
            "seconds_dop853": wall_dop,
            "B_evaluations": int(sol.stats.n_B_evaluations),
            "B_evaluations_dop853": nfev,
        }

    def figure(self, result: ExperimentResult) -> Figure:
        self._check_result(result)
        sweeps, long = result.data["sweeps"], result.data["long"]
        fig = new_figure(figsize=(9, 9.5))
        axes = fig.subplots(3, 2)
        styles = {"IsoMP": ("C0", "o-"), "RK4": ("C7", "v--"), "DOP853": ("k", "s:"),
                  "IsoSyRK(2)": ("C5", "D-"), "IsoSyRK(3)": ("C6", "D-")}  # fmt: skip
        for k, scheme in enumerate(SCHEMES):
            styles[f"IsoMP o {scheme}"] = (f"C{k + 1}", "^-")
        for row, (pname, sweep) in enumerate(sweeps.items()):
            for col, key in enumerate(("seconds", "B_evaluations")):
                ax = axes[row, col]
                for label, rec in sweep.items():
                    if rec["error"]:
                        color, style = styles[label]
                        ax.loglog(rec[key], _positive(rec["error"]), style, color=color, ms=4,
                                  lw=1, label=label)  # fmt: skip
                ax.set_xlabel("wall time [s]" if key == "seconds" else "evaluations of B")
                ax.set_ylabel("relative error at T")
                ax.set_title(f"{pname}, T = {result.summary['parameters']['T']:g}")
                ax.grid(True, which="major", alpha=0.3)
        axes[0, 0].legend(fontsize=7, ncol=2)
        ax = axes[2, 0]
        ax.semilogy(long["ts"], _positive(long["casimir_error"]), label=long["method"])
        ax.semilogy(long["ts"], _positive(long["casimir_error_dop853"]), "k:",
                    label=f"DOP853 (tol {long['dop853_tolerance']:.1e})")  # fmt: skip
        ax.set_title("rigid body: Casimir (eigenvalue) error, relative")
        ax.set_ylabel(r"$\max_j |\lambda_j(t) - \lambda_j(0)| / \|W_0\|$")
        ax = axes[2, 1]
        ax.semilogy(long["ts"], _positive(long["energy_error"]), label=long["method"])
        ax.semilogy(long["ts"], _positive(long["energy_error_dop853"]), "k:", label="DOP853")
        ax.set_title("rigid body: energy error, relative")
        ax.set_ylabel(r"$|H(t) - H(0)| / |H(0)|$")
        for ax in axes[2]:
            ax.set_xlabel("t")
            ax.legend(fontsize=8)
        fig.suptitle(
            "Work and precision: structure-preserving methods against RK4 and DOP853\n"
            f"(long run: h = {long['h']:.3g} over T = {result.summary['parameters']['T_long']:g})"
        )
        return fig


#: The experiment (call it to run it).
work_precision = WorkPrecision()
