"""
A sweep on a LocalCluster
=========================

``iso.sweep.run`` runs many members (parameters, seeds or a grid of them) as batched solves on a
dask.distributed cluster, each task writing its own resumable HDF5 file;
``iso.sweep.open_sweep`` reads the results back as one xarray Dataset with a ``member``
dimension. Sweeps need the extra ``pip install 'isoflow[sweep]'`` (dask, distributed, xarray);
the user guide's page on sweeps describes the file, the directory, faults and clusters.
"""

import tempfile

import numpy as np
from matplotlib.figure import Figure

import isoflow as iso

SPEC = {
    "model": "brockett",
    "method": "isomp",
    "dt": 0.1,
    "n_steps": 200,
    "save_every": 10,
    "members_per_task": 4,
    "params": {"n": 6},
    "grid": {"seed": {"start": 0, "stop": 8}},
}


def run_sweep(out):
    """Eight members (seeds 0..7) in two tasks on two worker processes."""
    from distributed import Client, LocalCluster

    with (
        LocalCluster(n_workers=2, threads_per_worker=1, processes=True) as cluster,
        Client(cluster) as client,
    ):
        iso.sweep.run(SPEC, out, client=client, progress=False)
    return iso.sweep.open_sweep(out).sortby("member")


if __name__ == "__main__":  # the worker processes import this file too; they run nothing
    ds = run_sweep(tempfile.mkdtemp())
    print(ds)

    # %%
    # The Lyapunov function ``Tr(W N)`` of every member against time.
    fig = Figure(figsize=(7, 3.6), layout="constrained")
    ax = fig.subplots()
    lyapunov = np.asarray(ds["lyapunov"])
    for k in range(lyapunov.shape[0]):
        seed = int(ds["seed"][k])
        ax.plot(np.asarray(ds["time"]), lyapunov[k], label=f"member {k} (seed {seed})")
    ax.set(
        xlabel="t", ylabel="Tr(W N)", title="Brockett flow, herm(6), 8 seeds on 2 workers, h = 0.1"
    )
    ax.legend(fontsize=7, ncol=2)
