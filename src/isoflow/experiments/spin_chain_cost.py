"""Section 3.3 of the paper (Fig. 3): time per step against the number of spins."""

from __future__ import annotations

import time
from typing import TYPE_CHECKING

import numpy as np

from .. import models
from .._figures import new_figure
from .._solve import solve
from ._base import Experiment, ExperimentResult, check, fit_order, header
from ._spin_chain import LABELS, METHODS, method

if TYPE_CHECKING:
    from matplotlib.figure import Figure

__all__ = ["SpinChainCost", "spin_chain_cost"]


class SpinChainCost(Experiment):
    """Average wall time per step against ``N``, IsoMP and the spherical midpoint (log–log)."""

    name = "spin-chain-cost"
    description = (
        "random spins, N = 10..1000: IsoMP and the spherical midpoint cost alike per step "
        "(Sec. 3.3, Fig. 3)"
    )

    def run(
        self,
        *,
        Ns: tuple[int, ...] = (10, 20, 50, 100, 200, 500, 1000),
        h: float = 0.1,
        n_steps: int = 50,
        repeats: int = 3,
        seed: int = 0,
        quick: bool = False,
        progress: bool | None = None,
    ) -> ExperimentResult:
        """Run the experiment.

        Paper, Sec. 3.3 (Fig. 3): random initial spins, the same fixed-point solver for both
        methods. The time per step is the best of ``repeats`` runs of ``n_steps`` steps.
        ``quick``: ``N = 10, 40, 160``, 10 steps, best of 3. Claims checked: the cost grows alike
        (fitted log–log slopes within 0.5 of each other) and IsoMP is at most 4 times as
        expensive per step.

        Returns
        -------
        ExperimentResult
            ``data``: ``Ns``, ``time_per_step`` (dict method -> array), ``iterations`` (mean
            per step, dict method -> array).
        """
        from tqdm.auto import tqdm

        if quick:
            Ns, n_steps, repeats = (10, 40, 160), 10, 3
        params = {"Ns": list(Ns), "h": h, "n_steps": n_steps, "repeats": repeats, "seed": seed}
        start = time.perf_counter()
        times = {k: np.empty(len(Ns)) for k in METHODS}
        iters = {k: np.empty(len(Ns)) for k in METHODS}
        bar = tqdm(
            total=len(Ns) * len(METHODS),
            desc=self.name,
            disable=None if progress is None else not progress,
            leave=False,
            delay=1.0,
        )
        with bar:
            for i, N in enumerate(Ns):
                problem, w0 = models.heisenberg_chain(N=N, initial="random", seed=seed)
                for key in METHODS:
                    # warm-up (compiled kernels, caches) outside the timing
                    solve(problem, method(key), w0, dt=h, n_steps=2, diagnostics=False,
                          progress=False)  # fmt: skip
                    best = np.inf
                    for _ in range(repeats):
                        sol = solve(
                            problem,
                            method(key),
                            w0,
                            dt=h,
                            n_steps=n_steps,
                            save_every=n_steps,
                            diagnostics=False,
                            progress=False,
                        )
                        best = min(best, sol.stats.wall_time / n_steps)
                    times[key][i] = best
                    iters[key][i] = sol.stats.iterations_mean
                    bar.update()
        Na = np.asarray(Ns, dtype=float)
        slopes = {k: fit_order(Na, v) for k, v in times.items()}
        ratio = times["isomp"] / times["spherical"]
        summary = header(self.name, params, quick) | {
            "time_per_step": {k: v.tolist() for k, v in times.items()},
            "iterations_mean": {k: v.tolist() for k, v in iters.items()},
            "loglog_slope": slopes,
            "time_ratio_isomp_over_spherical": ratio.tolist(),
            "checks": {
                "similar_growth": check(
                    abs(slopes["isomp"] - slopes["spherical"]),
                    0.5,
                    "the cost per step grows alike with N (log-log slopes)",
                ),
                "isomp_not_costlier": check(
                    float(np.max(ratio)),
                    4.0,
                    "IsoMP costs at most a small factor more than the spherical midpoint "
                    "(max time ratio isomp/spherical)",
                ),
            },
        }
        return self._result({"Ns": Na, "time_per_step": times, "iterations": iters}, summary, start)

    def figure(self, result: ExperimentResult) -> Figure:
        self._check_result(result)
        d, p = result.data, result.summary["parameters"]
        fig = new_figure(figsize=(6.5, 4.8))
        ax = fig.subplots()
        for key, style in (("isomp", "o-"), ("spherical", "s--")):
            ax.loglog(d["Ns"], d["time_per_step"][key], style, label=LABELS[key])
        ax.set_xlabel("spin particles N")
        ax.set_ylabel("wall time per step [s]")
        ax.set_title(
            f"Heisenberg chain, random spins: time per step\n(h = {p['h']:g}, best of "
            f"{p['repeats']} runs of {p['n_steps']} steps, fixed-point solver)"
        )
        ax.legend()
        return fig


#: The experiment (call it to run it).
spin_chain_cost = SpinChainCost()
