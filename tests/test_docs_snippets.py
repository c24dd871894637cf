"""Every Python example of the documentation runs as written.

Collected: the ``.. code-block:: python`` blocks and the ``>>>`` doctest blocks of
``docs/**/*.rst``, the fenced ``python`` blocks of ``README.md``, and the ``>>>``
examples in the docstrings of the package's modules. The blocks of one page run in order in one
namespace (as a reader pastes them into one session), as ``__main__``, in a fresh temporary
directory, with BLAS on one thread (``tests/conftest.py``); doctest output is compared with
``ELLIPSIS`` and ``NORMALIZE_WHITESPACE``. A failure names the file and the line.

The ``toml`` blocks are run or sweep files: each is read as the command line reads it (a
table with ``grid`` or ``members`` as a sweep file, any other as a run file) and must be valid.

A block that is deliberately incomplete (names defined in the prose, a cluster to connect to)
is marked as a fragment by a comment right before it: ``.. fragment`` in rst, ``<!-- fragment
-->`` in markdown, optionally with a reason (``.. fragment: needs a SLURM cluster``). A fragment
is only compiled, not run. ``docs/architecture.rst`` ("Building this site") documents this.
"""

from __future__ import annotations

import doctest
import importlib
import re
import runpy
import shutil
import textwrap
import tomllib
import traceback
from dataclasses import dataclass
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SRC = ROOT / "src" / "isoflow"
#: Directories and files of docs/ that the build generates (not sources; sphinx-gallery writes
#: ``sg_execution_times.rst`` beside ``index.rst``).
GENERATED = ("_build", "api", "auto_examples", "sg_execution_times.rst")

_RST_CODE = re.compile(r"^(\s*)\.\. (?:code-block|code|sourcecode)::\s*(python3?|py|pycon)\s*$")
_RST_DIRECTIVE = re.compile(r"^(\s*)\.\. [\w:-]+::")
_RST_FRAGMENT = re.compile(r"^\s*\.\. fragment\b")
_MD_FENCE = re.compile(r"^(\s*)```\s*(python3?|py|pycon)\s*$")
_MD_FRAGMENT = re.compile(r"^\s*<!--\s*fragment\b.*-->\s*$")
_DOCTEST_FLAGS = doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE
_RST_TOML = re.compile(r"^(\s*)\.\. (?:code-block|code|sourcecode)::\s*toml\s*$")
_MD_TOML = re.compile(r"^\s*```\s*toml\s*$")


@dataclass(frozen=True)
class Block:
    """One example: its code (dedented), where it starts, and how it runs."""

    path: str
    line: int  # 1-based line of the block's first line of code
    code: str
    doctest: bool
    fragment: bool


def _indent(line: str) -> int:
    return len(line) - len(line.lstrip())


def _previous_text(lines: list[str], i: int) -> str:
    """The nearest non-blank line before line ``i`` (0-based), or ``""``."""
    for j in range(i - 1, -1, -1):
        if lines[j].strip():
            return lines[j]
    return ""


def _indented_body(lines: list[str], start: int, indent: int) -> tuple[int, int]:
    """``(first, end)``: the lines after ``start`` indented deeper than ``indent`` (a
    directive's options and content, or a literal block), blank lines inside included."""
    end = start + 1
    last = start
    while end < len(lines) and (not lines[end].strip() or _indent(lines[end]) > indent):
        if lines[end].strip():
            last = end
        end += 1
    return start + 1, last + 1


def rst_blocks(text: str, path: str) -> list[Block]:
    """The Python blocks of an rst document (see the module docstring)."""
    lines = text.splitlines()
    blocks: list[Block] = []
    i = 0
    while i < len(lines):
        line = lines[i]
        fragment = bool(_RST_FRAGMENT.match(_previous_text(lines, i)))
        code = _RST_CODE.match(line)
        if code:
            first, end = _indented_body(lines, i, _indent(line))
            while first < end and (not lines[first].strip() or lines[first].strip()[0] == ":"):
                first += 1  # the directive's options and the blank line after them
            body = textwrap.dedent("\n".join(lines[first:end]))
            is_doctest = code.group(2) == "pycon" or body.lstrip().startswith(">>>")
            blocks.append(Block(path, first + 1, body, is_doctest, fragment))
            i = end
        elif _RST_DIRECTIVE.match(line) or line.rstrip().endswith("::"):
            i = _indented_body(lines, i, _indent(line))[1]  # other directives, literal blocks
        elif line.lstrip().startswith(">>>"):
            end = i
            while end < len(lines) and lines[end].strip():
                end += 1
            body = textwrap.dedent("\n".join(lines[i:end]))
            blocks.append(Block(path, i + 1, body, True, fragment))
            i = end
        else:
            i += 1
    return blocks


def markdown_blocks(text: str, path: str) -> list[Block]:
    """The fenced Python blocks of a markdown document (see the module docstring)."""
    lines = text.splitlines()
    blocks: list[Block] = []
    i = 0
    while i < len(lines):
        fence = _MD_FENCE.match(lines[i])
        if fence is None:
            i += 1
            continue
        end = i + 1
        while end < len(lines) and lines[end].strip() != "```":
            end += 1
        body = textwrap.dedent("\n".join(lines[i + 1 : end]))
        fragment = bool(_MD_FRAGMENT.match(_previous_text(lines, i)))
        is_doctest = fence.group(2) == "pycon" or body.lstrip().startswith(">>>")
        blocks.append(Block(path, i + 2, body, is_doctest, fragment))
        i = end + 1
    return blocks


def page_blocks(path: Path) -> list[Block]:
    """The Python blocks of one documentation page."""
    rel = str(path.relative_to(ROOT))
    text = path.read_text(encoding="utf-8")
    return markdown_blocks(text, rel) if path.suffix == ".md" else rst_blocks(text, rel)


def toml_blocks(path: Path) -> list[tuple[int, str]]:
    """``(line, text)`` of each ``toml`` block of a documentation page (rst or markdown)."""
    lines = path.read_text(encoding="utf-8").splitlines()
    found = []
    for i, line in enumerate(lines):
        if path.suffix == ".md" and _MD_TOML.match(line):
            end = next(j for j in range(i + 1, len(lines)) if lines[j].strip() == "```")
            found.append((i + 2, textwrap.dedent("\n".join(lines[i + 1 : end]))))
        elif path.suffix == ".rst" and _RST_TOML.match(line):
            first, end = _indented_body(lines, i, _indent(line))
            while first < end and (not lines[first].strip() or lines[first].strip()[0] == ":"):
                first += 1  # the directive's options and the blank line after them
            found.append((first + 1, textwrap.dedent("\n".join(lines[first:end]))))
    return found


def check_toml_block(text: str, where: str) -> None:
    """Read a ``toml`` block as ``isoflow sweep`` (a table with ``grid`` or ``members``) or
    ``isoflow run`` reads its file.

    Raises
    ------
    SnippetError
        ``where: what went wrong``.
    """
    from isoflow import registry
    from isoflow.sweep import read_spec

    try:
        table = tomllib.loads(text)
        if "grid" in table or "members" in table:
            read_spec(table)
        else:
            registry.normalize_config(registry.config_from_toml(table)[0])
    except Exception as exc:
        raise SnippetError(f"{where}: {type(exc).__name__}: {exc}") from exc


def _pages() -> list[Path]:
    docs = ROOT / "docs"
    rst = [p for p in sorted(docs.rglob("*.rst")) if p.relative_to(docs).parts[0] not in GENERATED]
    return [ROOT / "README.md", *rst]


class SnippetError(AssertionError):
    """A documentation example failed: the message starts with ``file:line:``."""


def _script(block: Block, directory: Path) -> Path:
    """The block written to a script in ``directory``, padded so that its lines are the
    page's (numba caches only functions that live in a file: ``@numba.njit(cache=True)``)."""
    name = re.sub(r"\W", "_", block.path) + f"_line{block.line}.py"
    path = directory / name
    path.write_text("\n" * (block.line - 1) + block.code + "\n", encoding="utf-8")
    return path


def _failure_line(exc: BaseException, script: Path, block: Block) -> int:
    """The line of the page where ``exc`` was raised (the innermost frame in the block)."""
    line = block.line
    for frame in traceback.extract_tb(exc.__traceback__):
        if frame.filename == str(script) and frame.lineno is not None:
            line = frame.lineno
    return line


def run_block(block: Block, namespace: dict[str, object], directory: Path) -> None:
    """Run (or, for a fragment, compile) one block in ``namespace``, as a script written to
    ``directory``.

    Raises
    ------
    SnippetError
        ``path:line: what went wrong``.
    """
    if block.doctest:
        _run_doctest(block, namespace)
        return
    script = _script(block, directory)
    try:
        code = compile(script.read_text(encoding="utf-8"), str(script), "exec")
    except SyntaxError as exc:
        raise SnippetError(f"{block.path}:{exc.lineno}: SyntaxError: {exc.msg}") from None
    if block.fragment:
        return
    try:
        exec(code, namespace)
    except Exception as exc:
        line = _failure_line(exc, script, block)
        first = str(exc).strip().splitlines()[0] if str(exc).strip() else ""
        raise SnippetError(f"{block.path}:{line}: {type(exc).__name__}: {first}") from exc


def _run_doctest(block: Block, namespace: dict[str, object]) -> None:
    parser = doctest.DocTestParser()
    try:
        test = parser.get_doctest(block.code, namespace, block.path, block.path, block.line - 1)
    except ValueError as exc:  # malformed (e.g. a missing blank after the prompt)
        raise SnippetError(f"{block.path}:{block.line}: malformed doctest: {exc}") from None
    if block.fragment:
        for example in test.examples:
            compile(example.source, block.path, "single")
        return
    report: list[str] = []
    runner = doctest.DocTestRunner(optionflags=_DOCTEST_FLAGS)
    runner.run(test, out=report.append, clear_globs=False)
    if runner.failures:
        where = re.search(r"line (\d+)", "".join(report))  # doctest counts from the page's top
        line = int(where.group(1)) if where else block.line
        raise SnippetError(f"{block.path}:{line}: doctest failed\n" + "".join(report))


def run_page(blocks: list[Block], directory: Path) -> None:
    """Run the blocks of one page in order in one namespace, in ``directory``; then drop what
    numba cached for functions the page defined (their scripts are gone after the test)."""
    namespace: dict[str, object] = {"__name__": "__main__"}
    try:
        for block in blocks:
            run_block(block, namespace, directory)
    finally:
        for value in namespace.values():
            cache_path = getattr(getattr(value, "_cache", None), "_cache_path", None)
            source = getattr(getattr(value, "py_func", None), "__code__", None)
            if cache_path and source and Path(source.co_filename).parent == directory:
                shutil.rmtree(cache_path, ignore_errors=True)


# ---- the collector itself ---------------------------------------------------------------------

RST = """\
Title
=====

Some prose::

    literal = block  # not Python to run

.. code-block:: python
   :caption: first

   x = 1
   y = x + 1

.. fragment: uses names from the prose

.. code-block:: python

   z = undefined_name

>>> y + 1
3

.. math::

   >>> not a doctest inside maths
"""

MARKDOWN = """\
# Title

```python
a = 2
```

<!-- fragment -->
```python
b = undefined_name
```

```bash
echo not python
```
"""


def test_the_collector_finds_blocks_lines_and_fragments(tmp_path: Path) -> None:
    blocks = rst_blocks(RST, "page.rst")
    assert [(b.line, b.code, b.doctest, b.fragment) for b in blocks] == [
        (11, "x = 1\ny = x + 1", False, False),
        (18, "z = undefined_name", False, True),
        (20, ">>> y + 1\n3", True, False),
    ]
    md = markdown_blocks(MARKDOWN, "README.md")
    assert [(b.line, b.code, b.fragment) for b in md] == [
        (4, "a = 2", False),
        (9, "b = undefined_name", True),
    ]
    run_page(blocks, tmp_path)  # the fragment is compiled, not run
    run_page(md, tmp_path)


@pytest.mark.parametrize(
    ("text", "message"),
    [
        (RST.replace(".. fragment: uses names from the prose", ""),
         "page.rst:18: NameError: name 'undefined_name' is not defined"),
        (RST.replace("3\n", "4\n"), "page.rst:20: doctest failed"),
        (RST.replace("y = x + 1", "y = (x +"), "page.rst:12: SyntaxError: "),
    ],
)  # fmt: skip
def test_a_failing_block_names_the_file_and_line(text: str, message: str, tmp_path: Path) -> None:
    with pytest.raises(SnippetError) as err:
        run_page(rst_blocks(text, "page.rst"), tmp_path)
    assert str(err.value).startswith(message), str(err.value)


def test_the_fragment_marker_is_documented() -> None:
    text = (ROOT / "docs" / "architecture.rst").read_text()
    assert ".. fragment" in text and "<!-- fragment -->" in text


# ---- the documentation --------------------------------------------------------------------------


@pytest.mark.parametrize(
    "page",
    [
        pytest.param(
            p,
            id=str(p.relative_to(ROOT)),
            marks=[pytest.mark.slow] if p.name == "README.md" else [],  # the first solve: ~10 s
        )
        for p in _pages()
    ],
)
def test_documentation_page_runs(
    page: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    blocks = page_blocks(page)
    if not blocks:
        pytest.skip("no Python blocks")
    monkeypatch.chdir(tmp_path)
    run_page(blocks, tmp_path)


def test_the_toml_collector_finds_run_and_sweep_files(tmp_path: Path) -> None:
    page = tmp_path / "page.rst"
    page.write_text(RST + '\n.. code-block:: toml\n\n   model = "rigid-body"\n   dt = 0.1\n')
    assert toml_blocks(page) == [(29, 'model = "rigid-body"\ndt = 0.1')]
    md = tmp_path / "page.md"
    md.write_text(MARKDOWN + '```toml\nmodel = "toda"\n```\n')
    assert toml_blocks(md) == [(16, 'model = "toda"')]
    check_toml_block('model = "rigid-body"\ndt = 0.1\nn_steps = 10\n[params]\nn = 4', "a:1")
    for text, message in [
        ('model = "rigid-body"\ndt = 0.1\nn_steps = 10\ncolour = 1', "a:1: ConfigError: "),
        ('model = "rigid-body"\ndt = 0.1\nn_steps = 10\n[grid]\nseed = []', "a:1: SweepError"),
        ("model = ", "a:1: TOMLDecodeError"),
    ]:
        with pytest.raises(SnippetError) as err:
            check_toml_block(text, "a:1")
        assert str(err.value).startswith(message), str(err.value)


@pytest.mark.parametrize(
    ("page", "line", "text"),
    [
        pytest.param(p, line, text, id=f"{p.relative_to(ROOT)}:{line}")
        for p in _pages()
        for line, text in toml_blocks(p)
    ],
)
def test_documentation_toml_files_are_valid(page: Path, line: int, text: str) -> None:
    check_toml_block(text, f"{page.relative_to(ROOT)}:{line}")


def _docstring_modules() -> list[str]:
    names = []
    for path in sorted(SRC.rglob("*.py")):
        if ">>>" in path.read_text(encoding="utf-8"):
            parts = path.relative_to(SRC.parent).with_suffix("").parts
            names.append(".".join(parts[:-1] if parts[-1] == "__init__" else parts))
    return names


@pytest.mark.parametrize("module", _docstring_modules())
def test_docstring_examples_run(
    module: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.chdir(tmp_path)
    mod = importlib.import_module(module)
    finder = doctest.DocTestFinder(exclude_empty=True)
    runner = doctest.DocTestRunner(optionflags=_DOCTEST_FLAGS)
    report: list[str] = []
    for test in finder.find(mod, module):
        runner.run(test, out=report.append)
    assert runner.failures == 0, "".join(report)


def test_the_gallery_shows_no_values_of_expressions() -> None:
    """sphinx-gallery would print the value of each cell's last expression (``Text(...)`` of a
    title, a ``Legend``): the examples end their cells with matplotlib calls."""
    conf = runpy.run_path(str(ROOT / "docs" / "conf.py"))
    assert conf["sphinx_gallery_conf"]["capture_repr"] == ()
