"""Check that the built site documents every public name of isoflow.

Reads the ``objects.inv`` of a built site and checks each name in the ``__all__`` of
``isoflow`` and of every public module (no part of its dotted name starts with ``_``). A name
counts as documented when it appears under its own full name or when the same object appears
under another documented name (``isoflow.IsoMP`` is described as ``isoflow.methods.IsoMP``;
``isoflow.models.ParameterError`` as ``isoflow.ParameterError``). Modules that cannot be
imported here (an optional dependency missing, or a module that does not exist in this version)
are listed and skipped.

Usage::

    python docs/check_api_coverage.py [docs/_build/html/objects.inv]

Exit status 0 when every name is documented, 1 otherwise.
"""

from __future__ import annotations

import importlib
import pkgutil
import sys
import types
import zlib
from pathlib import Path
from typing import Any

DEFAULT = Path(__file__).resolve().parent / "_build" / "html" / "objects.inv"
_MISSING = object()


def read_inventory(path: Path) -> dict[str, str]:
    """``name -> role`` of the Python objects in a Sphinx version-2 inventory."""
    with path.open("rb") as f:
        header = [f.readline() for _ in range(4)]
        if not header[0].startswith(b"# Sphinx inventory version 2"):
            raise SystemExit(f"{path}: not a Sphinx version-2 inventory")
        body = zlib.decompress(f.read()).decode()
    entries = {}
    for line in body.splitlines():
        name, role, *_ = line.split(" ", 2)
        if role.startswith("py:"):
            entries[name] = role
    return entries


def public_modules() -> tuple[list[types.ModuleType], dict[str, str]]:
    """``isoflow`` and every public submodule that imports; the others with the reason."""
    import isoflow

    modules = {"isoflow": isoflow}
    skipped = {}
    for info in pkgutil.walk_packages(isoflow.__path__, "isoflow.", onerror=lambda name: None):
        if any(part.startswith("_") for part in info.name.split(".")):
            continue
        try:
            modules[info.name] = importlib.import_module(info.name)
        except Exception as exc:
            skipped[info.name] = f"{type(exc).__name__}: {exc}"
    return [modules[k] for k in sorted(modules)], skipped


def resolve(dotted: str) -> Any:
    """The object named ``dotted`` (a module, then attributes), or ``_MISSING``."""
    parts = dotted.split(".")
    for i in range(len(parts), 0, -1):
        try:
            obj: Any = importlib.import_module(".".join(parts[:i]))
        except Exception:
            continue
        for attr in parts[i:]:
            obj = getattr(obj, attr, _MISSING)
            if obj is _MISSING:
                return _MISSING
        return obj
    return _MISSING


def main(argv: list[str]) -> int:
    path = Path(argv[1]) if len(argv) > 1 else DEFAULT
    if not path.exists():
        print(f"{path}: no inventory; build the site first", file=sys.stderr)
        return 1
    inventory = read_inventory(path)
    documented_ids = {}
    for name in inventory:
        obj = resolve(name)
        if obj is not _MISSING:
            documented_ids.setdefault(id(obj), []).append(name)

    modules, skipped = public_modules()
    missing, total = [], 0
    for module in modules:
        mod = module.__name__
        for name in getattr(module, "__all__", ()):
            total += 1
            full = f"{mod}.{name}"
            obj = getattr(module, name, _MISSING)
            # the same name as a module's (``isoflow.experiments.rigid_body`` is both the module
            # and, as an attribute of ``isoflow.experiments``, its experiment) counts only for a
            # module
            is_module = isinstance(obj, types.ModuleType)
            if full in inventory and (inventory[full] == "py:module") == is_module:
                continue
            if isinstance(obj, types.ModuleType):
                if obj.__name__ in inventory:
                    continue
            elif obj is not _MISSING:
                # the same object under another name: for constants (small ints and strings
                # are shared objects) only under the same name in another module
                others = documented_ids.get(id(obj), [])
                if isinstance(obj, type) or callable(obj):
                    if others:
                        continue
                elif any(o.rpartition(".")[2] == name for o in others):
                    continue
            missing.append(full)
    for name, reason in sorted(skipped.items()):
        print(f"skipped {name} (not importable here: {reason})")
    print(
        f"API coverage: {total - len(missing)} of {total} public names documented "
        f"in {len(modules)} modules ({path})"
    )
    for name in missing:
        print(f"  not documented: {name}")
    return 1 if missing else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
