"""``isoflow info``: what a result file holds, or a sweep directory's tasks and drifts."""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

from .. import registry
from ._common import sweep_task_note, table, threads_text

__all__ = ["add_parser", "handle"]


def add_parser(sub: Any) -> None:
    """Declare ``isoflow info`` on the subparsers ``sub``."""
    info = sub.add_parser(
        "info",
        help="describe a result file: parameters and invariant drifts",
        description=(
            "Describe an isoflow result file: the model and its parameters, the method, the "
            "time grid, how far the run got and whether it can be resumed (isoflow run "
            "--resume FILE), and the drift of every invariant over the saved states. On a "
            "sweep directory: its tasks, failed members and worst drifts."
        ),
    )
    info.add_argument("file", help="an isoflow result file (HDF5) or a sweep directory")
    info.add_argument("--json", action="store_true", help="print JSON")
    info.add_argument(
        "--verify",
        action="store_true",
        help="also check every saved state's checksum (a sweep: every task file's SHA-256)",
    )
    info.set_defaults(handler=handle, computes=False)


def handle(args: argparse.Namespace) -> int:
    """Print what a result file or a sweep directory holds (as JSON with ``--json``)."""
    if Path(args.file).is_dir():
        return _info_sweep(args)
    return _info_file(args)


def _info_file(args: argparse.Namespace) -> int:
    from .. import io

    data = io.info(args.file, verify_states=args.verify)
    if args.json:
        print(json.dumps(data, indent=2))
        return 0
    cfg, meta, run_info = data["config"], data["meta"], data["run_info"]
    sweep_note = sweep_task_note(args.file, cfg)
    message = data["state_message"]
    if sweep_note is not None:  # resumed by its sweep, not by isoflow run
        message = message.split("; resume with isoflow run --resume")[0]
    state = f"{data['state']}: {message}".rstrip(": ")
    model = str(cfg.get("model", "(not registered)"))
    if "model" in cfg and model not in registry.MODELS and sweep_note is None:
        model += " (not built in" + (
            f": resume with --model {model})" if data["resumable"] else ")"
        )
    rows = [
        ("model", f"{model} " + json.dumps(cfg.get("params", {}))),
        ("method", f"{meta.get('method')} (solver {cfg.get('solver') or 'none'})"),
        ("algebra", f"{meta.get('algebra')}, state shape {tuple(meta.get('state_shape'))}"),
        (
            "time grid",
            f"t0 = {meta.get('t0'):g}, dt = {meta.get('dt'):g}, {meta.get('n_steps')} steps, "
            f"save every {meta.get('save_every')}",
        ),
        ("state", state),
        (
            "resumable",
            ("yes" if data["resumable"] else "no")
            + (f" (writer: {data['writer']})" if data["writer"] else ""),
        ),
        (
            "format version",
            f"{data['format_version']}"
            + (", every saved state verified" if data["verified"] else ""),
        ),
        ("steps done", f"{data['step']}"),
        ("saved states", f"{data['n_saved']} (last t = {data['t_last']})"),
    ]
    if run_info is not None:
        st = run_info.get("stats", {})
        first = st.get("first_step", 0)
        part = f", steps {first + 1} to {st.get('n_steps')}: the resumed part" if first else ""
        rows.append(
            (
                "wall time",
                f"{st.get('wall_time', float('nan')):.2f} s "
                f"(iterations mean {st.get('iterations_mean', float('nan')):.2f}{part})",
            )
        )
        if isinstance(st.get("threads"), dict):  # older files do not record them
            rows.append(("threads", threads_text(st["threads"])))
    rows += [(k, f"{v:.3e}") for k, v in data["drifts"].items()]
    if sweep_note is not None:
        rows.append(("sweep", sweep_note))
    head = (
        f"{data['path']}: isoflow result file (written by isoflow {data['isoflow_version']}, "
        f"{data['created']})"
    )
    print("\n".join([head, *table(rows)]))
    return 0


def _info_sweep(args: argparse.Namespace) -> int:
    from ..sweep import status

    data = status(args.file, verify=args.verify)
    if args.json:
        print(json.dumps(data, indent=2))
        return 0
    run = data["run"]
    rows = [
        (
            "time grid",
            f"t0 = {run['t0']:g}, dt = {run['dt']:g}, {run['n_steps']} steps, "
            f"save every {run['save_every']}",
        ),
        (
            "members",
            f"{data['members']} in {data['tasks']} task"
            + ("" if data["tasks"] == 1 else "s")
            + ("" if data["perturb"] is None else f" (perturb {data['perturb']:g})"),
        ),
        (
            "tasks",
            f"{data['done']} done, {data['partial']} partial, {data['pending']} not started"
            + (f", {len(data['damaged'])} damaged" if data["damaged"] else "")
            + (", every result file verified" if args.verify else ""),
        ),
    ]
    rows += [(f"task {tid}", f"damaged: {msg}") for tid, msg in data["damaged"].items()]
    rows += [(f"task {tid}", f"raised: {msg}") for tid, msg in data["errors"].items()]
    rows += [
        (f"member {i}", f"failed at step {f['step']}: {f['message']}")
        for i, f in data["failed_members"].items()
    ]
    rows += [(k, f"{v:.3e} (worst finished member)") for k, v in data["drifts"].items()]
    head = f"{data['path']}: isoflow sweep, model {data['model']}, method {run.get('method')}"
    print("\n".join([head, *table(rows)]))
    return 0
