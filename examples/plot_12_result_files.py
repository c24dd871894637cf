"""
Result files: HDF5 streaming, xarray and netCDF
===============================================

``iso.solve(..., writer=iso.io.HDF5Writer(path))`` streams the saved states, their
invariants and a checkpoint to an HDF5 file chunk by chunk (memory does not grow with the
number of steps; a killed run resumes with ``iso.io.resume`` or ``isoflow run --resume``).
``iso.io.info`` summarizes a file without loading the states, ``iso.io.to_xarray`` reads it as
an :class:`xarray.Dataset`, ``iso.io.to_netcdf`` exports it.
"""

import json
import tempfile
from pathlib import Path

import numpy as np
import xarray as xr
from matplotlib.figure import Figure

import isoflow as iso

tmp = Path(tempfile.mkdtemp())
prob, w0 = iso.models.heisenberg_chain(N=20)
path = tmp / "chain.h5"
config = {"model": "spin-chain", "params": {"N": 20}, "dt": 0.1, "n_steps": 500}
sol = iso.solve(prob, iso.IsoMP(), w0, dt=0.1, n_steps=500, save_every=5,
                writer=iso.io.HDF5Writer(path, config))  # fmt: skip
print(sol.message)

info = iso.io.info(path)
print(json.dumps({k: info[k] for k in ("n_saved", "t_last", "complete", "drifts")}, indent=1))

# %%
# As an xarray Dataset: the states ``y`` with a ``time`` dimension and the diagnostic series.

ds = iso.io.to_xarray(path)
print(ds)

# %%
# A netCDF round trip: the exported file, read back with xarray, holds the same states.

nc = iso.io.to_netcdf(path, tmp / "chain.nc")
back = xr.open_dataset(nc, engine="h5netcdf")
print("netCDF round trip, largest difference:", float(np.abs(back["y"] - ds["y"]).max()))

fig = Figure(figsize=(7, 3.4), layout="constrained")
ax = fig.subplots()
for c, comp in enumerate("xyz"):
    ax.plot(back["time"], back["y"][:, 5, c], label=f"w_5.{comp} (from the netCDF file)")
ax.set(xlabel="t", title="spin chain N = 20, IsoMP, h = 0.1: spin 5 read back from netCDF")
ax.legend(fontsize=8)
back.close()
