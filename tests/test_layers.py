"""The package's import graph respects its layers (docs/architecture.md, "Layers", docs/models.md).

Every module of ``src/kesbrdf`` is parsed with :mod:`ast` (imports inside functions
count too: a lazy import is still a dependency), and the test fails when

* a module imports one of a higher layer, or
* a module imports another module's private (underscore) name — private *modules*
  such as ``kesbrdf._atomic`` or ``kesbrdf.cli._common`` are fine, and so are
  private names within one module.

Layers, lowest first (docs/architecture.md).  The paper's steps are folders:
``measure`` (acquire), ``models`` (interpolate and model; ``models.interpolation`` is
eq. 1-2 and sits below the kinds, ``models.base`` is the interface and registry beside
the model-file codec that looks it up) and ``validate``.  In the import graph the data
type ``measure.measurement`` sits below the readers that build it, and the direction
mappings at the bottom.  The applications are ordered too: ``cli`` over ``batch`` over
the four views (plotting, render, viewer, export) over ``cloth``, so that a batch step
importing the command line fails here.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

SRC = Path(__file__).resolve().parents[1] / "src"
PACKAGE = SRC / "kesbrdf"

#: (layer name, module-name prefixes).  A module belongs to the first layer with the
#: longest matching prefix.
LAYERS = [
    ("base", ["kesbrdf.errors", "kesbrdf._version", "kesbrdf._atomic", "kesbrdf._drjit", "kesbrdf.geometry", "kesbrdf.optics",
              "kesbrdf.models.mappings", "kesbrdf.references.marginal2d"]),
    ("measurement", ["kesbrdf.measure", "kesbrdf.measure.measurement"]),
    ("io", ["kesbrdf.io", "kesbrdf.models.base", "kesbrdf.references", "kesbrdf.measure.gonio",
            "kesbrdf.measure.acquisition", "kesbrdf.measure.demo_data"]),
    ("interpolate", ["kesbrdf.models.interpolation"]),
    ("model", ["kesbrdf.models"]),
    ("brdf", ["kesbrdf.models.brdf"]),
    ("validate", ["kesbrdf.validate"]),
    ("fitting", ["kesbrdf.fitting", "kesbrdf", "kesbrdf.measure.planning", "kesbrdf.pipeline"]),
    # The applications, in order: cli over batch over the four views over cloth.
    ("cloth", ["kesbrdf.cloth"]),
    ("views", ["kesbrdf.plotting", "kesbrdf.render", "kesbrdf.viewer", "kesbrdf.export"]),
    # the pipeline's steps that write through the views (report, export, preview); its
    # steps up to validation are at the fitting layer, so the views may call the fit
    ("pipeline outputs", ["kesbrdf.pipeline.outputs"]),
    ("batch", ["kesbrdf.batch"]),
    ("cli", ["kesbrdf.cli"]),
]


def module_name(path: Path) -> str:
    parts = list(path.relative_to(SRC).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts = parts[:-1]
    return ".".join(parts)


def is_module(name: str) -> bool:
    rel = Path(*name.split("."))
    return (SRC / rel).with_suffix(".py").is_file() or (SRC / rel / "__init__.py").is_file()


def layer_of(name: str) -> int:
    best, best_len = None, -1
    for rank, (_, prefixes) in enumerate(LAYERS):
        for p in prefixes:
            if (name == p or name.startswith(p + ".")) and len(p) > best_len:
                best, best_len = rank, len(p)
    if best is None:
        raise AssertionError(f"module {name} is in no layer: add it to LAYERS in tests/test_layers.py")
    return best


def resolve(module: str, node: ast.ImportFrom) -> str:
    if node.level:
        base = module.split(".")
        if not (PACKAGE / Path(*base[1:]) / "__init__.py").is_file() or module == "kesbrdf":
            base = base[:-1]
        base = base[: len(base) - (node.level - 1)]
        return ".".join(base + ([node.module] if node.module else []))
    return node.module or ""


def imports(path: Path, top_level_only: bool = False):
    """(imported module, private names taken from it, line) of one source file."""
    module = module_name(path)
    tree = ast.parse(path.read_text(encoding="utf-8"))
    nodes = tree.body if top_level_only else ast.walk(tree)
    for node in nodes:
        if isinstance(node, ast.Import):
            for alias in node.names:
                if alias.name.split(".")[0] == "kesbrdf":
                    yield alias.name, [], node.lineno
        elif isinstance(node, ast.ImportFrom):
            target = resolve(module, node)
            if target.split(".")[0] != "kesbrdf":
                continue
            names = [a.name for a in node.names]
            submodules = [n for n in names if is_module(f"{target}.{n}")]
            for n in submodules:
                yield f"{target}.{n}", [], node.lineno
            rest = [n for n in names if n not in submodules]
            if rest:
                private = [n for n in rest if n.startswith("_") and not n.startswith("__")]
                yield target, private, node.lineno


def modules():
    return sorted(p for p in PACKAGE.rglob("*.py") if "node_modules" not in p.parts)


def test_every_module_has_a_layer():
    for path in modules():
        layer_of(module_name(path))


def test_no_lower_layer_imports_a_higher_one():
    bad = []
    for path in modules():
        me = module_name(path)
        mine = layer_of(me)
        for target, _, line in imports(path):
            if target == me:
                continue
            theirs = layer_of(target)
            if theirs > mine:
                bad.append(f"{path.relative_to(SRC)}:{line}: {me} ({LAYERS[mine][0]}) imports "
                           f"{target} ({LAYERS[theirs][0]})")
    assert not bad, "\n".join(bad)


def test_no_module_imports_another_modules_private_names():
    bad = []
    for path in modules():
        me = module_name(path)
        for target, private, line in imports(path):
            if private and target != me:
                bad.append(f"{path.relative_to(SRC)}:{line}: imports {', '.join(private)} from {target}")
    assert not bad, "\n".join(bad)


def _cycle(graph):
    """One import cycle of ``graph`` (module -> imported modules) as a list, or None."""
    state = {}

    def visit(node, stack):
        state[node] = "open"
        for nxt in sorted(graph.get(node, ())):
            if state.get(nxt) == "open":
                return stack[stack.index(nxt):] + [nxt] if nxt in stack else [node, nxt]
            if nxt not in state:
                found = visit(nxt, stack + [nxt])
                if found:
                    return found
        state[node] = "done"
        return None

    for node in sorted(graph):
        if node not in state:
            found = visit(node, [node])
            if found:
                return found
    return None


def test_no_import_cycle_even_through_lazy_imports():
    """Issue 19: the three loops that lazy imports hid (kinds <-> io/model_file,
    export/__init__ <-> export/_framework, cloth/pattern <-> cloth/scenes) are gone, and
    no new one may appear: the graph of *all* imports, inside functions too, is acyclic."""
    graph = {module_name(p): {t for t, _, _ in imports(p) if t != module_name(p)} for p in modules()}
    cycle = _cycle(graph)
    assert cycle is None, "import cycle: " + " -> ".join(cycle)


def test_the_cycle_check_can_fail():
    assert _cycle({"a": {"b"}, "b": {"c"}, "c": {"a"}}) == ["a", "b", "c", "a"]
    assert _cycle({"a": {"b"}, "b": set()}) is None


def test_module_level_imports_have_no_cycle():
    """No import loop (issue 8: brdf <-> halfdiff <-> io/model_file <-> model): the graph
    of module-level imports is acyclic.  (A lazy import inside a function, such as
    ``ReflectanceModel.save`` importing the model-file writer, is not a loop at import
    time; the layer test above still constrains it.)"""
    graph = {}
    for path in modules():
        me = module_name(path)
        graph[me] = {t for t, _, _ in imports(path, top_level_only=True) if t != me}
    state = {}

    def visit(node, stack):
        state[node] = "open"
        for nxt in sorted(graph.get(node, ())):
            if state.get(nxt) == "open":
                cycle = stack[stack.index(nxt):] + [nxt] if nxt in stack else [node, nxt]
                raise AssertionError("import cycle: " + " -> ".join(cycle))
            if nxt not in state:
                visit(nxt, stack + [nxt])
        state[node] = "done"

    for node in sorted(graph):
        if node not in state:
            visit(node, [node])


@pytest.mark.parametrize("source,expected", [
    ("from kesbrdf.models.kes import _fill_table\n", "imports _fill_table from kesbrdf.models.kes"),
    ("from kesbrdf.plotting import figures\n", "kesbrdf.plotting.figures"),
])
def test_the_checker_sees_violations(tmp_path, monkeypatch, source, expected):
    """The checks can fail: a planted private import and a planted upward import."""
    fake = PACKAGE / "kes.py"
    monkeypatch.setattr(Path, "read_text", lambda self, encoding=None: source)
    found = list(imports(fake))
    target, private, _ = found[0]
    if "imports" in expected:
        assert private == ["_fill_table"] and target == "kesbrdf.models.kes"
    else:
        assert target == expected and layer_of(target) > layer_of("kesbrdf.models.interpolation")


#: Source-tree folders the installed package cannot see.  ``viewer/`` (the web viewer's
#: npm project, whose ``viewer/scripts/gltf-look.mjs`` the glTF look runs) is the one
#: allowed reach: a development tool's input, not data a model or reference needs.
_OUTSIDE_THE_PACKAGE = ("tests", "benchmarks", "docs")


#: Calls that join path parts: os.path.join, Path(...), PurePath(...), p.joinpath(...).
_JOINS = {"join", "joinpath", "Path", "PurePath"}


def _reaches_outside(source: str) -> list[str]:
    """Paths in ``source`` into a source-tree folder outside the package: a string (or an
    f-string's text) that starts ``tests/`` or ``./tests/`` (etc.), or the folder's name
    as an operand of a ``/`` path join or an argument of a joining call.  (A bare word
    elsewhere, such as a dict key ``"tests"``, is not a path.)"""
    def folder(part: str) -> str:
        part = part.replace("\\", "/")
        while part.startswith("./"):
            part = part[2:]
        return part.split("/", 1)[0]

    def is_folder(node) -> bool:
        return isinstance(node, ast.Constant) and isinstance(node.value, str) and folder(node.value) in _OUTSIDE_THE_PACKAGE

    found = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Constant) and isinstance(node.value, str):
            if "/" in node.value and is_folder(node):
                found.append(node.value)
        elif isinstance(node, ast.JoinedStr):  # f"{root}/tests/data": the text after a value
            for part in node.values:
                if isinstance(part, ast.Constant) and isinstance(part.value, str):
                    text = part.value.lstrip("/")
                    if "/" in part.value and folder(text) in _OUTSIDE_THE_PACKAGE:
                        found.append(part.value)
        elif isinstance(node, ast.BinOp) and isinstance(node.op, ast.Div):
            found += [side.value for side in (node.left, node.right) if is_folder(side)]
        elif isinstance(node, ast.Call):
            name = node.func.attr if isinstance(node.func, ast.Attribute) else getattr(node.func, "id", "")
            if name in _JOINS:
                found += [arg.value for arg in node.args if is_folder(arg)]
    return sorted(set(found), key=found.index)


def test_the_package_reads_nothing_from_the_source_tree():
    """Issue 19: the references' registry found the white felt in ``tests/data``, which an
    installed package does not have.  Data the package needs ships in ``kesbrdf/data``.
    Docstrings mention test files as prose; the check looks at code only."""
    bad = {}
    for path in modules():
        tree = ast.parse(path.read_text(encoding="utf-8"))
        for n in ast.walk(tree):
            if isinstance(n, (ast.Module, ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)) and n.body \
                    and isinstance(n.body[0], ast.Expr) and isinstance(n.body[0].value, ast.Constant):
                n.body[0] = ast.Pass()
        hits = _reaches_outside(ast.unparse(tree))
        if hits:
            bad[module_name(path)] = hits
    assert not bad, f"modules that read the source tree outside the package: {bad}"


@pytest.mark.parametrize("source, expected", [
    ('Path(here).parents[3] / "tests" / "data" / "rgl"', ["tests"]),
    ('open("tests/data/x.csv")', ["tests/data/x.csv"]),
    ('open("./tests/x")', ["./tests/x"]),
    ('os.path.join(root, "tests", "data")', ["tests"]),
    ('Path(root, "benchmarks")', ["benchmarks"]),
    ('root.joinpath("docs")', ["docs"]),
    ('f"{root}/tests/data"', ["/tests/data"]),
    ('row["tests"] = 1; print("the tests pass")', []),
])
def test_the_source_tree_check_can_fail(source, expected):
    assert _reaches_outside(source) == expected
