"""The house rules that keep the code findable: one source for every default, layers that
import only downward, no import cycles, small modules."""
import ast
import os
import sys

import pytest

from ctseg.params import ALIASES, SPECS

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
CODE_DIRS = ("ctseg", "filters", "plugin")
SPEC_FILE = os.path.join(ROOT, "ctseg", "params.py")
# the simulator's own seed is the phantom's, not the segmentation's parameter
NOT_STAGES = {os.path.join(ROOT, "ctseg", "phantoms.py"), os.path.join(ROOT, "ctseg", "phantoms3d.py")}
PAPER_DEFAULTS = (SPECS["lam"].default, SPECS["beta"].default)


def _code_files():
    for top in CODE_DIRS:
        for folder, _, names in os.walk(os.path.join(ROOT, top)):
            for name in sorted(names):
                if name.endswith(".py"):
                    yield os.path.join(folder, name)


def _spec_names(key):
    if key in SPECS:
        return (key,)
    return ALIASES.get(key, ())


def _retyped_defaults(path):
    """(line, what) of every place a spec default is written as a literal again: a keyword
    default or a keyword argument of a spec parameter's name equal to its default, and
    the paper's lambda and beta anywhere."""
    tree = ast.parse(open(path).read(), path)
    found = []

    def is_default(name, node):
        return isinstance(node, ast.Constant) and any(
            type(node.value) is type(SPECS[n].default) and node.value == SPECS[n].default
            for n in _spec_names(name))

    for node in ast.walk(tree):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda)):
            args = node.args
            pos = args.posonlyargs + args.args
            pairs = list(zip(pos[len(pos) - len(args.defaults):], args.defaults))
            pairs += [(a, d) for a, d in zip(args.kwonlyargs, args.kw_defaults) if d is not None]
            found += [(d.lineno, f"default {a.arg}={d.value!r}") for a, d in pairs
                      if is_default(a.arg, d)]
        elif isinstance(node, ast.Call):
            found += [(k.value.lineno, f"argument {k.arg}={k.value.value!r}")
                      for k in node.keywords if k.arg and is_default(k.arg, k.value)]
        elif isinstance(node, ast.Dict):
            found += [(v.lineno, f"entry {k.value!r}: {v.value!r}") for k, v in zip(node.keys, node.values)
                      if isinstance(k, ast.Constant) and isinstance(k.value, str) and is_default(k.value, v)]
        if (isinstance(node, ast.Constant) and type(node.value) in (int, float)
                and node.value in PAPER_DEFAULTS):
            found.append((node.lineno, f"the paper's {node.value!r}"))
    return found


def test_defaults_are_written_only_in_the_spec():
    bad = []
    for path in _code_files():
        if path == SPEC_FILE or path in NOT_STAGES:
            continue
        bad += [f"{os.path.relpath(path, ROOT)}:{line}: {what}" for line, what in _retyped_defaults(path)]
    assert not bad, "defaults retyped outside ctseg/params.py:\n" + "\n".join(bad)


def test_the_literal_check_catches_a_retyped_default(tmp_path):
    """The check above can fail: each way of retyping a default is found."""
    src = tmp_path / "bad.py"
    src.write_text("def f(x, lam=70.0, tol_px=0.01):\n    return g(init='ward', sigma=1.0)\n"
                   "D = {'max_iter': 200}\nBETA = 0.286\n")
    whats = [w for _, w in _retyped_defaults(str(src))]
    assert "default tol_px=0.01" in whats and "argument init='ward'" in whats
    assert "argument sigma=1.0" in whats and "entry 'max_iter': 200" in whats
    assert sum("paper" in w for w in whats) == 2


def test_spec_defaults_are_spec_values():
    # every default passes its own check (a range or a type typo in the spec fails here)
    for spec in SPECS.values():
        assert spec.check(spec.default) == spec.default, spec.name


def test_no_module_over_400_lines():
    long = [f"{os.path.relpath(p, ROOT)}: {n}" for p in _code_files()
            for n in [sum(1 for _ in open(p))] if n > 400]
    assert not long, long


def test_plugins_are_glue():
    """The ParaView and Slicer files import ctseg only through the filters, the spec and
    the errors (plus the phantoms in self-tests), never the algorithm modules."""
    allowed = ("ctseg.filters", "ctseg.params", "ctseg.errors", "ctseg.raster")
    bad = []
    for folder in ("paraview", "slicer"):
        for path in _code_files():
            if f"plugin{os.sep}{folder}" not in path or os.path.basename(path).startswith("test_"):
                continue
            for node in ast.walk(ast.parse(open(path).read())):
                names = ([a.name for a in node.names] if isinstance(node, ast.Import)
                         else [node.module or ""] if isinstance(node, ast.ImportFrom) and not node.level
                         else [])
                bad += [f"{os.path.relpath(path, ROOT)}: {n}" for n in names
                        if n.split(".")[0] == "ctseg" and n != "ctseg"
                        and not n.startswith(allowed) and not n.startswith("ctseg.phantoms")
                        and not n.startswith("ctseg.metrics")]
    assert not bad, bad


grimp = pytest.importorskip("grimp", reason="grimp comes with import-linter (the lint extra)")


def test_no_import_cycles():
    """No cycle among ctseg's modules, imports inside functions included."""
    sys.path.insert(0, ROOT)
    try:
        graph = grimp.build_graph("ctseg", include_external_packages=False)
    finally:
        sys.path.remove(ROOT)
    modules = sorted(graph.modules)
    edges = {m: set(graph.find_modules_directly_imported_by(m)) & set(modules) for m in modules}
    index, low, stack, on, cycles = {}, {}, [], set(), []

    def visit(v):  # Tarjan's strongly connected components
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in edges[v]:
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
            # a package importing its own submodules is not a cycle of modules
            comp = [c for c in comp if not any(o.startswith(c + ".") for o in comp)]
            if len(comp) > 1:
                cycles.append(sorted(comp))

    for m in modules:
        if m not in index:
            visit(m)
    assert not cycles, cycles


def test_layer_contract_names_every_algorithm_module():
    """The import-linter contract in pyproject.toml lists ctseg's modules by hand: a new
    module must join it (or the layers would not cover it)."""
    tomllib = pytest.importorskip("tomllib")
    with open(os.path.join(ROOT, "pyproject.toml"), "rb") as fh:
        config = tomllib.load(fh)
    contract = config["tool"]["importlinter"]["contracts"][0]
    listed = set(contract["source_modules"])
    present = {f"ctseg.{name[:-3]}" for name in os.listdir(os.path.join(ROOT, "ctseg"))
               if name.endswith(".py") and name not in ("__init__.py", "cli.py")}
    assert listed == present, (sorted(present - listed), sorted(listed - present))
    assert {"vtk", "vtkmodules", "ctseg.filters", "ctseg.cli"} <= set(contract["forbidden_modules"])
