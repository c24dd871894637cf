"""A method's settings as a flat record, kept in result files and compared on resume.

Two methods with one :attr:`~isoflow.Method.name` may still take different steps: another
solver tolerance, Anderson memory, extrapolation degree, compensation or update. A run records
:func:`method_settings` of its method when it starts (``meta["method_settings"]``), and
:func:`isoflow.io.resume` refuses a method whose settings differ (unless ``force``), so that a
resumed run continues on the path it began.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np

__all__ = ["method_settings", "settings_changes"]


def _value(v: Any) -> Any:
    """A JSON-ready form of a setting's value."""
    if v is None or isinstance(v, (bool, int, float, str)):
        return v
    if isinstance(v, np.generic):
        return v.item()
    if isinstance(v, (tuple, list)):
        return [_value(x) for x in v]
    return repr(v)


def method_settings(method: Any) -> dict[str, Any]:
    """``{dotted field: value}`` of ``method``'s constructor arguments, through nested
    dataclasses (a solver, a composed or split base), with each dataclass's class name.

    Parameters
    ----------
    method : Method
        A method (a dataclass, as every isoflow method is).

    Returns
    -------
    dict
        E.g. ``{"class": "IsoMP", "solver.class": "FixedPoint", "solver.rtol": 1e-14, ...,
        "update": "midpoint"}``; private and derived fields (``init=False``) are left out.
    """
    out: dict[str, Any] = {}

    def walk(obj: Any, prefix: str) -> None:
        out[prefix + "class"] = type(obj).__name__
        for f in dataclasses.fields(obj):
            if not f.init or f.name.startswith("_"):
                continue
            v = getattr(obj, f.name)
            if dataclasses.is_dataclass(v) and not isinstance(v, type):
                walk(v, f"{prefix}{f.name}.")
            else:
                out[prefix + f.name] = _value(v)

    if dataclasses.is_dataclass(method) and not isinstance(method, type):
        walk(method, "")
    return out


def settings_changes(recorded: Any, now: dict[str, Any]) -> list[str]:
    """The settings that differ between a file's record and ``now`` (``"key: then -> now"``).

    Only keys in both are compared: a setting added to a method after the file was written
    took its default then (and files written before settings were recorded have none).

    Parameters
    ----------
    recorded : dict or None
        The file's ``meta["method_settings"]``.
    now : dict
        :func:`method_settings` of the method given to resume.

    Returns
    -------
    list of str
        Empty when the settings agree (or the file has no record).
    """
    if not isinstance(recorded, dict):
        return []
    return [
        f"{k}: {recorded[k]!r} -> {now[k]!r}"
        for k in sorted(set(recorded) & set(now))
        if recorded[k] != now[k]
    ]
