"""Sphinx helpers of the isoflow documentation.

- :func:`write_api_pages` writes ``docs/api/*.rst`` from the ``__all__`` of every public module
  at each build (a module is public when no part of its dotted name starts with ``_``), so a new
  module appears in the reference without editing any page. Each object is described once, under
  its *canonical* name (the shortest public name: ``isoflow.IsoMP``, not
  ``isoflow.methods.isomp.IsoMP``); other modules that export it list it with a link.
- :func:`resolve_short_names` resolves the short names docstrings use (``Solution``,
  ``IsoMP.advance``, ``io.load``) to the documented objects, and renders names of other
  libraries (numpy, scipy, matplotlib, xarray, ...) as plain code: no intersphinx inventory can
  be fetched where the site is built.
- :func:`figure_scraper` is the gallery's image scraper. isoflow builds its figures as
  :class:`matplotlib.figure.Figure` objects without pyplot, so the scraper collects every such
  figure bound to a name of the example (directly or in a list, tuple or dict) that it has not
  shown yet.
- The ``benchmark-table`` directive renders ``benchmarks/results/benchmarks.json`` when it exists.
"""

from __future__ import annotations

import builtins
import importlib
import inspect
import json
import pkgutil
import re
import sys
import types
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from docutils import nodes
from docutils.parsers.rst import Directive
from docutils.statemachine import StringList

ROOT = Path(__file__).resolve().parents[2]
API_DIR = Path(__file__).resolve().parents[1] / "api"

#: Top-level packages whose names are rendered as plain code when they cannot be resolved.
EXTERNAL = (
    "numpy",
    "np",
    "scipy",
    "matplotlib",
    "mpl_toolkits",
    "xarray",
    "h5py",
    "h5netcdf",
    "numba",
    "dask",
    "distributed",
    "threadpoolctl",
    "ducc0",
    "tqdm",
    "collections",
    "typing",
    "os",
    "pathlib",
    "abc",
    "enum",
    "dataclasses",
    "concurrent",
    "json",
    "tomllib",
    "importlib",
    "argparse",
    "numpy.typing",
    "datetime",
    "io",
    "contextlib",
    "functools",
    "signal",
)


# --------------------------------------------------------------------------- public modules


def public_modules() -> tuple[list[types.ModuleType], dict[str, str]]:
    """Import ``isoflow`` and every public submodule that can be imported.

    Returns the modules (sorted by name) and, for each module that could not be imported
    (e.g. one whose optional dependency is missing), the reason.
    """
    import isoflow

    modules = {"isoflow": isoflow}
    skipped: dict[str, str] = {}
    for info in pkgutil.walk_packages(isoflow.__path__, "isoflow.", onerror=lambda name: None):
        if any(part.startswith("_") for part in info.name.split(".")):
            continue
        try:
            modules[info.name] = importlib.import_module(info.name)
        except Exception as exc:  # an optional dependency missing: documented as skipped
            skipped[info.name] = f"{type(exc).__name__}: {exc}"
    return [modules[k] for k in sorted(modules)], skipped


def exported(module: types.ModuleType) -> list[tuple[str, Any]]:
    """``(name, object)`` for each name of ``module.__all__`` (names that fail to load skipped)."""
    out = []
    for name in getattr(module, "__all__", ()):
        try:
            out.append((name, getattr(module, name)))
        except Exception:
            continue
    return out


def _public_prefix(dotted: str) -> str:
    parts = []
    for part in dotted.split("."):
        if part.startswith("_"):
            break
        parts.append(part)
    return ".".join(parts)


def kind(obj: Any) -> str:
    """The autodoc directive that describes ``obj``."""
    if isinstance(obj, types.ModuleType):
        return "module"
    if inspect.isclass(obj):
        return "exception" if issubclass(obj, BaseException) else "class"
    if callable(obj) and hasattr(obj, "__module__") and not isinstance(obj, type):
        return "function"
    return "data"


def canonical_names(modules: list[types.ModuleType]) -> dict[tuple[str, str], str]:
    """Map ``(module, name)`` of every export to the full name it is documented under."""
    exports: dict[int, list[tuple[str, str, Any]]] = {}
    for module in modules:
        for name, obj in exported(module):
            exports.setdefault(id(obj), []).append((module.__name__, name, obj))
    names = {m.__name__ for m in modules}
    result: dict[tuple[str, str], str] = {}
    for entries in exports.values():
        obj = entries[0][2]
        if isinstance(obj, types.ModuleType):
            for mod, name, _ in entries:
                result[(mod, name)] = obj.__name__
            continue
        k = kind(obj)
        if k == "data":
            # constants: the same value may be exported under different names; group by name
            by_name: dict[str, list[str]] = {}
            for mod, name, _ in entries:
                by_name.setdefault(name, []).append(mod)
            for name, mods in by_name.items():
                home = min(mods, key=lambda m: (m.count("."), m))
                for mod in mods:
                    result[(mod, name)] = f"{home}.{name}"
            continue
        # the shortest public name users reach it by (``isoflow.IsoMP`` rather than
        # ``isoflow.methods.isomp.IsoMP``); among equally short ones, the module it comes from
        home_module = _public_prefix(getattr(obj, "__module__", "") or "")
        candidates = sorted({mod for mod, _, _ in entries if mod in names})
        # not a name that is also a module's (``isoflow.experiments.rigid_body`` is the module;
        # its experiment is described as ``isoflow.experiments.rigid_body.rigid_body``)
        free = [m for m, n, _ in entries if m in names and f"{m}.{n}" not in names]
        candidates = sorted(set(free)) or candidates
        home = min(
            candidates,
            key=lambda m: (m.count("."), not (home_module + ".").startswith(m + "."), m),
        )
        home_name = next(name for mod, name, _ in entries if mod == home)
        for mod, name, _ in entries:
            result[(mod, name)] = f"{home}.{home_name}"
    return result


# --------------------------------------------------------------------------- API pages


def _title(text: str, char: str = "=") -> list[str]:
    return [text, char * len(text), ""]


def write_api_pages(app: Any = None) -> list[str]:
    """Write ``docs/api/index.rst`` and one page per public module; returns the module names."""
    modules, skipped = public_modules()
    canon = canonical_names(modules)
    API_DIR.mkdir(exist_ok=True)
    written = set()
    for module in modules:
        mod = module.__name__
        lines = [f".. This page is generated by docs/_ext/isoflow_docs.py from {mod}.__all__.", ""]
        lines += _title(f"``{mod}``")
        lines += [f".. automodule:: {mod}", "   :no-members:", ""]
        here, elsewhere, submodules = [], [], []
        for name, obj in exported(module):
            target = canon[(mod, name)]
            if isinstance(obj, types.ModuleType):
                submodules.append((name, target))
            elif target == f"{mod}.{name}":
                here.append((name, obj))
            else:
                elsewhere.append((name, target))
        if submodules:
            lines += _title("Submodules", "-")
            lines += [f"- :py:mod:`{mod}.{name} <{target}>`" for name, target in submodules]
            lines.append("")
        if elsewhere:
            lines += _title("Also exported here", "-")
            lines += [
                f"- ``{mod}.{name}``: :py:obj:`{target} <{target}>`" for name, target in elsewhere
            ]
            lines.append("")
        if here:
            lines += _title("Contents", "-")
            lines += [".. currentmodule:: " + mod, ""]
            for name, obj in here:
                k = kind(obj)
                if k in ("class", "exception"):
                    lines += [f".. auto{k}:: {name}", "   :members:", "   :show-inheritance:", ""]
                elif k == "function":
                    lines += [f".. autofunction:: {name}", ""]
                else:
                    lines += [f".. autodata:: {name}", "   :no-value:", ""]
                    if _doc_comment(module, name) is None:  # autodoc reads this source only
                        comment = _defining_comment(module, name, obj)
                        text = comment or [
                            f"Exported constant ``{mod}.{name}`` ({type(obj).__name__})."
                        ]
                        lines += [f"   {line}".rstrip() for line in text] + [""]
        page = API_DIR / f"{mod}.rst"
        _write_if_changed(page, "\n".join(lines) + "\n")
        written.add(page.name)
    index = [".. This page is generated by docs/_ext/isoflow_docs.py.", ""]
    index += _title("API reference")
    index += [
        "Generated at every build from the ``__all__`` of ``isoflow`` and of each public module",
        "(no part of its dotted name starts with an underscore). An object exported by several",
        "modules is described once, under its shortest public name (``isoflow.IsoMP``, not",
        "``isoflow.methods.isomp.IsoMP``), and listed with a link in the others.",
        "",
        ".. toctree::",
        "   :maxdepth: 1",
        "",
    ]
    index += [f"   {m.__name__}" for m in modules]
    if skipped:
        index += ["", "Not importable in this build (an optional dependency is missing):", ""]
        index += [f"- ``{name}``: {reason}" for name, reason in sorted(skipped.items())]
    _write_if_changed(API_DIR / "index.rst", "\n".join(index) + "\n")
    written.add("index.rst")
    for old in API_DIR.glob("*.rst"):
        if old.name not in written:
            old.unlink()
    return [m.__name__ for m in modules]


def _doc_comment(module: types.ModuleType, name: str) -> list[str] | None:
    """The ``#:`` comment lines above the assignment of ``name`` in the module's source."""
    try:
        source = inspect.getsource(module)
    except (OSError, TypeError):
        return None
    lines = source.splitlines()
    for i, line in enumerate(lines):
        if line.startswith((f"{name} =", f"{name}:")) and i > 0 and lines[i - 1].startswith("#:"):
            start = i
            while start > 0 and lines[start - 1].startswith("#:"):
                start -= 1
            return [ln[2:].strip() for ln in lines[start:i]]
    return None


def _defining_comment(module: types.ModuleType, name: str, obj: Any) -> list[str] | None:
    """The ``#:`` comment of a constant that ``module`` re-exports from one of its own
    submodules (``isoflow.registry.MODELS`` is defined in ``isoflow.registry._catalogue``), where
    autodoc, reading only ``module``'s source, does not look."""
    prefix = module.__name__ + "."
    for other in sorted(n for n in sys.modules if n.startswith(prefix)):
        mod = sys.modules[other]
        if mod is not None and getattr(mod, name, _MISSING) is obj:
            comment = _doc_comment(mod, name)
            if comment is not None:
                return comment
    return None


def _write_if_changed(path: Path, text: str) -> None:
    if not path.exists() or path.read_text() != text:
        path.write_text(text)


# --------------------------------------------------------------------------- references


def resolve_short_names(app: Any, env: Any, node: Any, contnode: Any) -> Any:
    """``missing-reference`` handler for the names docstrings use.

    In order: a documented name that ends with the target (``Solution`` ->
    ``isoflow.Solution``, preferring the current module); an isoflow object documented under
    another name (``isoflow.IsospectralProblem`` is described as
    ``isoflow.problems.IsospectralProblem``); an importable isoflow name that is not part of the
    API (private helpers, attributes) or a name of another library, rendered as plain code.
    Anything else stays unresolved, so ``nitpicky`` reports it.
    """
    if node.get("refdomain") != "py":
        return None
    target = node.get("reftarget", "").lstrip("~.")
    if target.startswith("iso."):
        target = "isoflow." + target[4:]
    module, cls = node.get("py:module"), node.get("py:class")
    domain = env.get_domain("py")
    candidates = [target]
    if module and cls:
        candidates.append(f"{module}.{cls}.{target}")
    if module:
        candidates.append(f"{module}.{target}")
    candidates.append(f"isoflow.{target}")
    owner = _import(f"{module}.{cls}") if module and cls else _MISSING
    if owner is _MISSING and module:
        owner = _import(f"{module}.{node.get('reftarget', '').split('.')[0]}")
    real = getattr(owner, "__module__", None)
    if isinstance(real, str) and real.startswith("isoflow") and real != module:
        candidates.append(f"{real}.{target}")
    found = _lookup(domain, candidates, module)
    if found is None:
        for name in candidates:
            obj = _import(name)
            if obj is not _MISSING:
                documented = _documented_ids(env).get(id(obj))
                if documented is not None:
                    found = documented
                    break
                if name.startswith("isoflow"):
                    return nodes.literal("", contnode.astext())
            elif "." in name and inspect.isclass(_import(name.rpartition(".")[0])):
                # an instance attribute (a dataclass field, an attribute set in __init__)
                if name.startswith("isoflow"):
                    return nodes.literal("", contnode.astext())
    if found is not None:
        return domain.resolve_xref(env, node["refdoc"], app.builder, "obj", found, node, contnode)
    loaded = [mod for name, mod in list(sys.modules.items()) if name.startswith("isoflow")]
    # a helper of the module the docstring comes from, not part of the API
    if "." not in target and any(hasattr(mod, target) for mod in loaded):
        return nodes.literal("", contnode.astext())
    head = target.split(".")[0]
    if head in EXTERNAL or hasattr(builtins, head) or head in ("Array", "ArrayLike", "Self"):
        return nodes.literal("", contnode.astext())
    return None


_MISSING = object()
_IDS: dict[int, str] = {}


def _import(dotted: str) -> Any:
    """The object named ``dotted`` (a module, then attributes), or ``_MISSING``."""
    parts = dotted.split(".")
    if not parts[0]:
        return _MISSING
    for i in range(len(parts), 0, -1):
        try:
            obj = importlib.import_module(".".join(parts[:i]))
        except Exception:
            continue
        for attr in parts[i:]:
            try:
                obj = getattr(obj, attr)
            except Exception:
                return _MISSING
        return obj
    return _MISSING


def _documented_ids(env: Any) -> dict[int, str]:
    """``id(object) -> documented name`` for every class and function in the py domain."""
    if not _IDS:
        for name, entry in env.get_domain("py").objects.items():
            if entry.objtype in ("class", "exception", "function", "method", "property"):
                obj = _import(name)
                if obj is not _MISSING:
                    _IDS.setdefault(id(obj), name)
    return _IDS


def _lookup(domain: Any, candidates: list[str], module: str | None) -> str | None:
    objects = domain.objects
    for name in candidates:
        if name in objects:
            return name
    target = candidates[0]
    matches = [name for name in objects if name.endswith("." + target)]
    if not matches:
        return None
    if module:
        near = [m for m in matches if m.startswith(module + ".")]
        if near:
            matches = near
    return min(matches, key=lambda m: (m.count("."), m))


# --------------------------------------------------------------------------- docstrings

_SECTIONS = {"Parameters", "Returns", "Yields", "Attributes", "Other Parameters", "Receives"}


_NOTES = re.compile(r"(?:/work/shared/paper/|\.\./shared/paper/)?NOTES\.md")


def escape_type_stars(app: Any, what: str, name: str, obj: Any, options: Any, lines: list) -> None:
    """Escape ``*`` and ``|`` in numpydoc type lines (``shape (*batch, n, n)``,
    ``shape (N - |m|,)``), which reST would read as emphasis and substitutions.

    Also points the docstrings' mentions of the paper's notes (a file outside this repository)
    at the site's own list of corrections.
    """
    for i, line in enumerate(lines):
        if "NOTES.md" in line:
            lines[i] = _NOTES.sub(":ref:`the corrections to the paper <corrections>`", line)
    section, indent = None, None
    for i, line in enumerate(lines):
        stripped = line.strip()
        if i + 1 < len(lines) and set(lines[i + 1].strip()) == {"-"} and stripped:
            section, indent = stripped, None
            continue
        if section not in _SECTIONS or not stripped or set(stripped) == {"-"}:
            continue
        ind = len(line) - len(line.lstrip())
        if indent is None:
            indent = ind
        if ind != indent:
            continue
        if " : " in line:
            head, _, typ = line.partition(" : ")
            lines[i] = head + " : " + _escape(typ)
        elif section in ("Returns", "Yields", "Receives"):
            lines[i] = _escape(line)


def _escape(text: str) -> str:
    out, literal = [], False
    for j, ch in enumerate(text):
        if text.startswith("``", j):
            literal = not literal
        if ch in "*|" and not literal and (j == 0 or text[j - 1] != "\\"):
            out.append("\\" + ch)
        else:
            out.append(ch)
    return "".join(out)


# --------------------------------------------------------------------------- gallery

_SHOWN: set[int] = set()


def _figures(value: Any, depth: int = 0) -> Iterator[Any]:
    from matplotlib.figure import Figure

    if isinstance(value, Figure):
        yield value
    elif depth == 0 and isinstance(value, list | tuple):
        for item in value:
            yield from _figures(item, 1)
    elif depth == 0 and isinstance(value, dict):
        for item in value.values():
            yield from _figures(item, 1)


def figure_scraper(block: Any, block_vars: dict[str, Any], gallery_conf: dict[str, Any]) -> str:
    """Save the figures an example's block made (pyplot-free ``Figure`` objects) as images."""
    from sphinx_gallery.scrapers import figure_rst

    paths = []
    iterator = block_vars["image_path_iterator"]
    for value in list(block_vars["example_globals"].values()):
        for fig in _figures(value):
            if id(fig) in _SHOWN:
                continue
            _SHOWN.add(id(fig))
            path = next(iterator)
            fig.savefig(path, dpi=90)
            paths.append(path)
    return figure_rst(paths, gallery_conf["src_dir"])


def reset_figures(gallery_conf: dict[str, Any], fname: str) -> None:
    """Forget the figures shown by the previous example."""
    _SHOWN.clear()


# --------------------------------------------------------------------------- benchmark table


class BenchmarkTable(Directive):
    """Render ``benchmarks/results/benchmarks.json`` as a table, or say how to produce it."""

    has_content = False

    def run(self) -> list[Any]:
        path = ROOT / "benchmarks" / "results" / "benchmarks.json"
        if not path.exists():
            text = [
                ".. note::",
                "",
                "   No benchmark results in this checkout. Produce them (``--quick`` for a first",
                "   look, ``--only 1,2`` for a subset) and rebuild the site::",
                "",
                "      python benchmarks/run_all.py --out benchmarks/results",
            ]
        else:
            report = json.loads(path.read_text())
            machine = report.get("machine", {})
            summary = ", ".join(f"{k} {v}" for k, v in machine.items() if not isinstance(v, dict))
            text = [f"Machine: {summary}.", ""]
            if report.get("note"):
                text += [str(report["note"]).rstrip(".") + ".", ""]
            text += [".. list-table::", "   :header-rows: 1", ""]
            header = ["#", "benchmark", "measured", "target", "met"]
            text += ["   * - " + header[0]] + [f"     - {c}" for c in header[1:]]
            for row in report.get("results", []):
                cells = [
                    row.get("id", ""),
                    row.get("name", ""),
                    f"{row.get('metric', '')} {_fmt(row.get('value'))}",
                    row.get("target", ""),
                    {True: "yes", False: "no"}.get(row.get("met"), "-"),
                ]
                text.append(f"   * - {cells[0]}")
                text += [f"     - {c}" for c in cells[1:]]
        node = nodes.section()
        node.document = self.state.document
        self.state.nested_parse(StringList(text, source=str(path)), self.content_offset, node)
        return list(node.children)


def _fmt(value: Any) -> str:
    if isinstance(value, float):
        return f"{value:.3g}"
    return "" if value is None else str(value)


def drop_type_docstrings(
    app: Any, what: str, name: str, obj: Any, options: Any, lines: list
) -> None:
    """Drop the docstring of a constant's type (``int([x]) -> integer ...``), which autodoc
    shows for a constant without a ``#:`` comment in the module it reads (one re-exported from
    another module): the page gives the comment found where it is defined, or says what the
    constant is (:func:`write_api_pages`)."""
    doc = getattr(type(obj), "__doc__", None)
    if what == "data" and doc and " ".join(" ".join(lines).split()) == " ".join(doc.split()):
        lines.clear()


def setup(app: Any) -> dict[str, Any]:
    app.connect("builder-inited", write_api_pages)
    app.connect("missing-reference", resolve_short_names)
    app.connect("autodoc-process-docstring", escape_type_stars, priority=400)
    app.connect("autodoc-process-docstring", drop_type_docstrings, priority=300)
    app.add_directive("benchmark-table", BenchmarkTable)
    return {"version": "1", "parallel_read_safe": True, "parallel_write_safe": True}
