"""Rewriting the valid part of a result file into a fresh version 2 file.

A file killed while in HDF5's SWMR write mode keeps its "open for writing" flags, so HDF5 will
not open it for writing again; a version 1 file has no checksums. :func:`recover` copies the
rows up to the last checkpoint (verified against their checksums where the file has them), the
checkpoint and the attributes into ``<path>.recover``, block by block (bounded memory), and
then replaces the file with it.
"""

from __future__ import annotations

import contextlib
import os
from pathlib import Path

import h5py

from .._errors import ResultWriteError
from .layout import Handles, create_layout, write_attrs
from .reader import Checkpoint, iter_rows, open_result, read_checkpoint
from .safefile import SafeFile

__all__ = ["recover"]


def recover(path: Path, chunk_rows: int = 256) -> Checkpoint:
    """Rewrite the valid part of ``path`` as a closed version 2 file; return its checkpoint.

    The caller holds the file's write lock.

    Parameters
    ----------
    path : Path
        The result file.
    chunk_rows : int
        Rows copied per block of the new file (default 256).

    Returns
    -------
    Checkpoint
        The checkpoint of the rewritten file.

    Raises
    ------
    ResultFileError
        The file is not readable, has no checkpoint, or its rows are damaged.
    ResultWriteError
        Writing the copy failed (the original file is left as it was).
    """
    tmp = path.with_name(path.name + ".recover")
    sf = SafeFile(tmp, create=True)
    try:
        with open_result(path, check_live=False) as src:
            cp = read_checkpoint(src)
            if cp is None:
                raise src.fail("no checkpoint to resume from (start the run again)")
            created = src.f.attrs.get("created", "?")
            names = list(src.rows)
            with h5py.File(sf, "w", libver="latest") as dst:
                write_attrs(dst, src.config, src.meta)
                dst.attrs["created"] = created
                rows = src.rows
                create_layout(
                    dst, tuple(rows["ys"].shape[1:]), rows["ys"].dtype,
                    {k: (tuple(rows[k].shape[1:]), rows[k].dtype) for k in names[2:]},
                    int(src.f["checkpoint"]["slot0"]["failures"].shape[0]), chunk_rows,
                )  # fmt: skip
                h = Handles(dst)
                for blocks, data in iter_rows(src, cp, names):
                    lo = blocks[0][0]
                    for a, b in blocks:  # the same blocks: the same checksums
                        h.write_block(
                            data["ts"][a - lo : b - lo],
                            data["ys"][a - lo : b - lo],
                            {k: data[k][a - lo : b - lo] for k in names[2:]},
                        )
                h.write_slot(0, cp.step, cp.y, cp.method_state, cp.failures, cp.run_info)
                h.point_to(0)
        err = sf.error
    except BaseException:
        sf.close()
        with contextlib.suppress(OSError):
            tmp.unlink()
        raise
    sf.close()
    if err is not None:
        with contextlib.suppress(OSError):
            tmp.unlink()
        raise ResultWriteError(
            f"{path}: rewriting the file for resume failed ({err.strerror or err}); "
            "the file is unchanged"
        )
    os.replace(tmp, path)
    return Checkpoint(
        cp.step, cp.n_rows, 0, cp.y, cp.method_state, cp.failures, h.n_blocks, cp.run_info
    )
