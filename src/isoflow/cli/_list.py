"""``isoflow list``: the models, methods, solvers and experiments, by the names to use."""

from __future__ import annotations

import argparse
from typing import Any

from .. import registry

__all__ = ["add_parser", "handle"]


def add_parser(sub: Any) -> None:
    """Declare ``isoflow list`` on the subparsers ``sub``."""
    lst = sub.add_parser(
        "list", help="the models, methods, solvers and experiments, by the names to use"
    )
    lst.add_argument(
        "what",
        nargs="?",
        choices=("models", "methods", "solvers", "experiments"),
        help="one kind only (default: all)",
    )
    lst.set_defaults(handler=handle, computes=False)


def handle(args: argparse.Namespace) -> int:
    """Print the names the other commands take, with their descriptions and parameters."""
    kinds = [args.what] if args.what else ["models", "methods", "solvers", "experiments"]
    lines: list[str] = []
    for kind in kinds:
        lines.append(f"{kind}:")
        for name, text, params in registry.describe(kind):
            lines.append(f"  {name:<34} {text}")
            lines += [f"  {'':<34}   {p}" for p in params]
    if "models" in kinds:
        lines.append(
            "  (your own: --model package.module:factory; packages register models under the "
            f"entry-point group {registry.ENTRY_POINT_GROUP})"
        )
    print("\n".join(lines))
    return 0
