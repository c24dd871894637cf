"""
A sweep on a LocalCluster
=========================

``iso.sweep`` runs many members (parameters, seeds or a grid of them) as batched solves on a
dask.distributed cluster, each task writing its own resumable HDF5 file; ``open_sweep`` reads
the results back as one xarray Dataset with a ``member`` dimension. This example needs
``isoflow.sweep`` and its extra (dask, distributed); where they are missing it prints a note
and stops.
"""

import importlib.util
import tempfile

import numpy as np
from matplotlib.figure import Figure

import isoflow as iso


def available(name):
    try:
        return importlib.util.find_spec(name) is not None
    except ModuleNotFoundError:
        return False


if not (available("isoflow.sweep") and available("distributed")):
    print("isoflow.sweep (or dask.distributed) is not available in this installation: skipped.")
else:
    from distributed import Client, LocalCluster

    spec = {
        "model": "brockett",
        "method": "isomp",
        "dt": 0.1,
        "n_steps": 200,
        "save_every": 10,
        "members_per_task": 4,
        "params": {"n": 6},
        "grid": {"seed": {"start": 0, "stop": 8}},
    }
    out = tempfile.mkdtemp()
    with (
        LocalCluster(n_workers=2, threads_per_worker=1, processes=True) as cluster,
        Client(cluster) as client,
    ):
        iso.sweep(spec, out, client=client, progress=False)
    open_sweep = getattr(iso.io, "open_sweep", None) or iso.sweep.open_sweep
    ds = open_sweep(out).sortby("member")
    print(ds)

    # %%
    # The Lyapunov function ``Tr(W N)`` of every member against time.
    fig = Figure(figsize=(7, 3.6), layout="constrained")
    ax = fig.subplots()
    series = np.asarray(ds["lyapunov"]) if "lyapunov" in ds else None
    if series is not None:
        for k in range(series.shape[0]):
            ax.plot(
                np.asarray(ds["time"]), series[k], label=f"member {k} (seed {int(ds['seed'][k])})"
            )
        ax.set(xlabel="t", ylabel="Tr(W N)",
               title="Brockett flow, herm(6), 8 seeds on 2 workers, h = 0.1")  # fmt: skip
        ax.legend(fontsize=7, ncol=2)
