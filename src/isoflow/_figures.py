"""Small helpers shared by every figure of the package (experiments, result files).

Figures are :class:`matplotlib.figure.Figure` objects built directly (no ``pyplot``, no global
backend state), so they render headless; matplotlib is imported only when a figure is made.
"""

from __future__ import annotations

import os
import tempfile
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from ._flags import check_flag

if TYPE_CHECKING:
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

__all__ = [
    "DPI",
    "SUFFIXES",
    "eigenvalue_figure",
    "floor",
    "new_figure",
    "plot_indexed_variations",
    "plot_variation",
    "save",
]

#: Resolution of the PNG files.
DPI = 90
#: File types :func:`save` writes.
SUFFIXES = (".png", ".pdf", ".svg")


def new_figure(**kwargs: Any) -> Figure:
    """A :class:`~matplotlib.figure.Figure` with constrained layout (``kwargs`` as for it)."""
    from matplotlib.figure import Figure

    return Figure(layout="constrained", **kwargs)


def save(fig: Figure, path: str | os.PathLike[str], *, force: bool = False) -> Path:
    """Write ``fig`` to ``path`` (the format from the suffix: .png, .pdf or .svg).

    The figure is written to a temporary file beside ``path`` and renamed over it, so a
    failed write leaves no half file.

    Parameters
    ----------
    fig : matplotlib.figure.Figure
    path : str or Path
        The image file; its directory must exist.
    force : bool
        Replace an existing file. Only a regular file is ever replaced (never a directory, a
        device or another special file).

    Raises
    ------
    ParameterError
        ``force`` that is not a bool.
    ValueError
        Another suffix.
    FileExistsError
        ``path`` exists and ``force`` is false, or it is not a regular file.
    FileNotFoundError
        The directory of ``path`` does not exist (it is not created: a mistyped path).
    """
    check_flag(force, "force")  # "no" would count as true
    p = Path(path)
    if p.suffix.lower() not in SUFFIXES:
        raise ValueError(f"{p}: choose a .png, .pdf or .svg file name")
    folder = p.parent if str(p.parent) else Path(".")
    if not folder.is_dir():
        raise FileNotFoundError(f"{p}: no directory {folder} to write it in")
    if p.exists() or p.is_symlink():
        if not p.is_file():
            raise FileExistsError(f"{p} exists and is not a regular file; not replacing it")
        if not force:
            raise FileExistsError(f"{p} exists (use --force / force=True to replace it)")
    fd, tmp = tempfile.mkstemp(prefix=f".{p.name}.", suffix=p.suffix, dir=p.parent or ".")
    try:
        with os.fdopen(fd, "wb") as fh:
            fig.savefig(fh, dpi=DPI, format=p.suffix[1:].lower())
        os.chmod(tmp, 0o644)
        os.replace(tmp, p)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return p


def floor(x: Any) -> Any:
    """``|x|`` with zeros lifted to the smallest positive double, for log axes."""
    return np.maximum(np.abs(np.asarray(x, dtype=float)), 1e-300)


def plot_variation(
    ax: Axes,
    x: Any,
    y: Any,
    *,
    ylabel: str,
    labels: Sequence[str] | None = None,
    legend_columns: int = 1,
    **kwargs: Any,
) -> None:
    """Plot curves ``y`` (``(len(x),)`` or ``(len(x), m)``) with their scale in the label.

    Values of order ``10^k`` far from 1 (variations at rounding level, ``1e-15``) are divided by
    ``10^k`` and the label says so, instead of matplotlib's offset text at the top of the axis,
    which collides with a panel title. ``labels`` names the curves (a legend is drawn).
    """
    Y = np.asarray(y, dtype=float)
    amax = float(np.max(np.abs(Y))) if Y.size else 0.0
    k = int(np.floor(np.log10(amax))) if amax > 0 and np.isfinite(amax) else 0
    if -2 <= k <= 3:
        k = 0
    lines = ax.plot(x, Y / 10.0**k, **kwargs)
    ax.set_ylabel(ylabel + (f"  [$10^{{{k}}}$]" if k else ""))
    ax.ticklabel_format(axis="y", useOffset=False, style="plain")
    if labels is not None:
        for line, label in zip(lines, labels, strict=True):
            line.set_label(label)
        ax.legend(fontsize=7, ncol=legend_columns, loc="best", framealpha=0.7)


def plot_indexed_variations(ax: Axes, x: Any, y: Any, *, ylabel: str, symbol: str) -> None:
    """:func:`plot_variation` of the columns of ``y``, labelled ``symbol_1``, ``symbol_2``, ..."""
    Y = np.asarray(y)
    m = Y.shape[1] if Y.ndim > 1 else 1
    plot_variation(ax, x, Y, lw=0.8, ylabel=ylabel, legend_columns=max(1, m // 2),
                   labels=[rf"${symbol}_{{{j + 1}}}$" for j in range(m)])  # fmt: skip


def eigenvalue_figure(ts: Any, variation: Any, of: str) -> tuple[Figure, Axes]:
    """A two-panel figure (shared time axis) whose top panel shows the variation of each
    eigenvalue ``lambda_j(t) - lambda_j(0)`` of the matrix named ``of`` (TeX); returns the
    figure and the bottom axes, for the experiment's second quantity."""
    fig = new_figure(figsize=(7.5, 6))
    ax1, ax2 = fig.subplots(2, 1, sharex=True)
    plot_indexed_variations(ax1, ts, variation, symbol=r"\lambda",
                            ylabel=r"$\lambda_j(t) - \lambda_j(0)$")  # fmt: skip
    ax1.set_title(f"Casimirs: variation of the eigenvalues of ${of}$")
    ax2.set_xlabel("t")
    return fig, ax2
