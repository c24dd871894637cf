"""The shape of the package: a light ``import isoflow``, no import cycles, one-way layers."""

from __future__ import annotations

import ast
import json
import subprocess
import sys
from pathlib import Path

import pytest

import isoflow as iso

SRC = Path(iso.__file__).resolve().parent
#: Modules that ``import isoflow`` (and the command line before it runs a command) must not load.
HEAVY = (
    "h5py", "matplotlib", "numba", "tqdm", "ducc0", "xarray", "scipy.integrate", "dask",
    "distributed",
)  # fmt: skip

#: Known import edges that close a cycle, each with the reason it is still there (none now).
ALLOWED_CYCLE_EDGES: set[tuple[str, str]] = set()


def _loaded_after(code: str) -> list[str]:
    probe = f"{code}\nimport sys, json\nprint(json.dumps(sorted(sys.modules)))"
    out = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True,
                         check=True, timeout=120)  # fmt: skip
    return json.loads(out.stdout.strip().splitlines()[-1])


@pytest.mark.parametrize(
    "code",
    [
        "import isoflow",
        "import isoflow.cli; isoflow.cli.build_parser()",
        "import isoflow.registry",
        "import isoflow as iso; iso.sweep; import isoflow.sweep.spec",  # dask loads when run
    ],
)
def test_import_is_light(code: str) -> None:
    loaded = _loaded_after(code)
    heavy = [m for m in loaded if any(m == h or m.startswith(h + ".") for h in HEAVY)]
    assert heavy == [], f"{code!r} loads {sorted({m.split('.')[0] for m in heavy})}"


def test_lazy_attributes_load_on_use() -> None:
    loaded = _loaded_after("import isoflow as iso; iso.io; iso.models.rigid_body; iso.__version__")
    assert "h5py" in loaded and "isoflow.models._rigid_body" in loaded
    assert "matplotlib" not in loaded
    for name in (
        "io",
        "experiments",
        "plotting",
        "registry",
        "sphere",
        "sweep",
        "threads",
        "models",
    ):
        assert name in dir(iso) and name in iso.__all__
    with pytest.raises(AttributeError, match="no attribute 'nonexistent'"):
        iso.nonexistent  # noqa: B018


def _modules() -> dict[str, tuple[Path, bool]]:
    out = {}
    for path in SRC.rglob("*.py"):
        parts = list(path.relative_to(SRC.parent).with_suffix("").parts)
        is_pkg = parts[-1] == "__init__"
        out[".".join(parts[:-1] if is_pkg else parts)] = (path, is_pkg)
    return out


def _imports(tree: ast.AST) -> list[ast.Import | ast.ImportFrom]:
    """Every import statement, also inside functions, except under ``if TYPE_CHECKING:``."""
    found: list[ast.Import | ast.ImportFrom] = []
    stack = [tree]
    while stack:
        node = stack.pop()
        if isinstance(node, ast.If) and "TYPE_CHECKING" in ast.unparse(node.test):
            stack.extend(node.orelse)
            continue
        if isinstance(node, ast.Import | ast.ImportFrom):
            found.append(node)
        stack.extend(ast.iter_child_nodes(node))
    return found


def import_graph() -> dict[str, set[str]]:
    """Module -> the package modules it imports (``from . import x`` counts as ``x`` only)."""
    mods = _modules()
    graph: dict[str, set[str]] = {m: set() for m in mods}
    for mod, (path, is_pkg) in mods.items():
        for node in _imports(ast.parse(path.read_text())):
            if isinstance(node, ast.Import):
                targets = [a.name for a in node.names]
            else:
                base = node.module or ""
                if node.level:
                    parts = mod.split(".")[: len(mod.split(".")) - (0 if is_pkg else 1)]
                    parts = parts[: len(parts) - (node.level - 1)]
                    base = ".".join(parts + ([node.module] if node.module else []))
                targets = [f"{base}.{a.name}" if f"{base}.{a.name}" in mods else base
                           for a in node.names]  # fmt: skip
            for t in targets:
                while t and t not in mods:
                    t = t.rpartition(".")[0]
                if t and t != mod:
                    graph[mod].add(t)
    # the package root's lazy attributes (PEP 562) import these on first use
    graph["isoflow"] |= {f"isoflow.{m}" for m in iso._LAZY_MODULES}
    return graph


def _cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components with more than one module (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on: set[str] = set()
    out: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in graph[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    for v in graph:
        if v not in index:
            visit(v)
    return out


def test_no_import_cycles() -> None:
    graph = import_graph()
    for a, b in ALLOWED_CYCLE_EDGES:
        graph.get(a, set()).discard(b)
    cycles = _cycles(graph)
    detail = [[f"{v} -> {w}" for v in c for w in sorted(graph[v]) if w in c] for c in cycles]
    assert cycles == [], detail


def test_the_cycle_finder_finds_cycles() -> None:
    assert _cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]
    assert _cycles({"a": {"b"}, "b": set()}) == []


def test_layers_depend_one_way() -> None:
    graph = import_graph()

    def package(name: str) -> set[str]:
        return {m for m in graph if m == name or m.startswith(name + ".")}

    experiments = package("isoflow.experiments")
    cli = package("isoflow.cli")
    app = {"isoflow.plotting", *cli, *package("isoflow.registry"), *experiments}
    app |= package("isoflow.sweep")
    for m in experiments:
        assert "isoflow.plotting" not in graph[m] and not graph[m] & cli, m
    assert not experiments & graph["isoflow.plotting"] - {"isoflow.experiments"}
    core = {
        m for m in graph if m not in app and not m.startswith(("isoflow.io", "isoflow._compiled"))
    }
    for m in core - {"isoflow"}:
        assert not graph[m] & app, f"{m} imports the application layer: {graph[m] & app}"


def test_no_package_is_callable_or_binds_a_submodule_name_lazily() -> None:
    """Importing ``package.x`` sets the package's attribute ``x`` to the module. A package that
    binds its public names lazily (a module ``__getattr__``, as ``isoflow.models`` does) would
    then answer with the module or the function by import order, so none of those names is a
    submodule's; and no package swaps its ``__class__`` (to be callable, or to fight this)."""
    code = (
        "import importlib, json, pkgutil, types\n"
        "import isoflow\n"
        "names = ['isoflow'] + [m.name for m in pkgutil.walk_packages(isoflow.__path__, "
        "'isoflow.') if m.ispkg]\n"
        "bad = []\n"
        "for name in names:\n"
        "    pkg = importlib.import_module(name)\n"
        "    if type(pkg) is not types.ModuleType:\n"
        "        bad.append(f'{name} is a {type(pkg).__name__}')\n"
        "    lazy = {n for n in getattr(pkg, '__all__', ()) if n not in vars(pkg)}\n"
        "    for n in lazy & {m.name for m in pkgutil.iter_modules(pkg.__path__)}:\n"
        "        if not isinstance(getattr(pkg, n), types.ModuleType):\n"
        "            bad.append(f'{name}.{n} is bound lazily and is also a module')\n"
        "print(json.dumps(bad))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True, timeout=120)  # fmt: skip
    assert json.loads(out.stdout.strip().splitlines()[-1]) == []
