"""The layer contract of the package: each sub-package imports only the layers below it,
at module level (no import inside a function to dodge a cycle), and there is no import
cycle among the modules. Read from the files themselves with ast, so it fails the moment a
reversed import is written (shown once: ``from ..simulation.runner import simulate`` in
``hybrid/start.py`` fails ``test_every_import_goes_down``)."""

from __future__ import annotations

import ast
import importlib.util
from pathlib import Path

import pytest

# found without importing it: the contract holds (and fails readably) even where a
# reversed import makes the package itself fail to import
PKG = Path(importlib.util.find_spec("cmm_dae").origin).resolve().parent

#: The layers, bottom first; a module may import its own layer and those before it.
LAYERS = ["core", "description", "equations", "hybrid", "singular", "integrators", "results",
          "simulation", "sensitivity", "studies", "report"]
#: Modules above every layer.
TOP = {"__init__", "cli", "cli_commands"}


def _modules():
    for f in sorted(PKG.rglob("*.py")):
        rel = f.relative_to(PKG).with_suffix("")
        yield f, rel.parts


def _imports(f: Path, parts: tuple[str, ...]):
    """(target top-level part of cmm_dae, line, inside a function) of every relative or
    absolute import of cmm_dae in the file."""
    tree = ast.parse(f.read_text())
    funcs = [n for n in ast.walk(tree) if isinstance(n, ast.FunctionDef | ast.AsyncFunctionDef)]
    inside = {id(x) for fn in funcs for x in ast.walk(fn)}
    typing_only = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.If) and "TYPE_CHECKING" in ast.unparse(node.test):
            typing_only |= {id(x) for x in ast.walk(node)}
    pkg_parts = parts[:-1]
    for node in ast.walk(tree):
        if not isinstance(node, ast.ImportFrom) or id(node) in typing_only:
            continue
        if node.level:
            base = list(pkg_parts[:len(pkg_parts) - node.level + 1])
            mod = (node.module or "").split(".") if node.module else []
            full = base + [m for m in mod if m]
            if not full:  # from . import x (the package root): x is the target
                full = [node.names[0].name]
        elif node.module and node.module.split(".")[0] == "cmm_dae":
            full = node.module.split(".")[1:] or [node.names[0].name]
        else:
            continue
        yield full[0], node.lineno, id(node) in inside


def layer_of(top: str) -> int:
    return len(LAYERS) if top in TOP else LAYERS.index(top)


@pytest.mark.parametrize("f,parts", list(_modules()), ids=lambda x: str(x))
def test_every_import_goes_down(f, parts):
    here = parts[0]
    if here in TOP:  # the package root and the command line may import any layer
        return
    mine = layer_of(here)
    for target, line, _ in _imports(f, parts):
        if target in TOP or target.startswith("_"):
            assert here in TOP, f"{f}:{line} imports the top ({target})"
            continue
        assert target in LAYERS, f"{f}:{line} imports cmm_dae.{target}, not a layer"
        assert layer_of(target) <= mine, (
            f"{f.relative_to(PKG)}:{line}: layer '{here}' imports '{target}', a layer above it")


def test_no_import_hidden_in_a_function():
    """Every import of cmm_dae is at module level (where the layer test sees it, and
    where a cycle fails at once), but in the command line, which imports a command's
    modules when it runs (start-up time) and in the package root's old-path hook."""
    bad = []
    for f, parts in _modules():
        if parts[0] in TOP:
            continue
        bad += [f"{f.relative_to(PKG)}:{line} -> {target}"
                for target, line, inside in _imports(f, parts) if inside]
    assert not bad


#: what a function may import itself: the optional extras (a user without them gets the
#: rest of the package), matplotlib where a report picks its backend first
LATE = {"pandas", "mujoco", "exudyn", "distributed", "matplotlib", "importlib"}
#: ... and where, of the required libraries: scikit-sundae where a Python-path solver is
#: made or its memory or messages are read (the compiled path never imports it; scipy's
#: optimizers, splines and quadrature pass through core/scipy_late.py, by importlib).
#: Those imports were half of ``import cmm_dae``; scipy itself and scikit-sundae's
#: presence are still checked at import (scipy.linalg at the top of the modules that
#: use it, ``find_spec`` in csegment.py).
LATE_IN = {"integrators/ida_steps.py": {"sksundae"},
           "integrators/csegment.py": {"sksundae"},
           "integrators/suppress.py": {"sksundae"}}


def test_only_optional_libraries_are_imported_late():
    """Outside the command line, a function imports only the optional extras or
    matplotlib (backend first); every other library at the top of its module, where a
    missing dependency fails the import at once instead of halfway through a run."""
    bad = []
    for f, parts in _modules():
        if parts[0] in TOP and parts[0] != "__init__":
            continue
        tree = ast.parse(f.read_text())
        for fn in ast.walk(tree):
            if not isinstance(fn, ast.FunctionDef | ast.AsyncFunctionDef):
                continue
            for node in ast.walk(fn):
                if isinstance(node, ast.Import):
                    names = [a.name for a in node.names]
                elif isinstance(node, ast.ImportFrom) and not node.level:
                    names = [node.module or ""]
                else:
                    continue
                here = LATE | LATE_IN.get(str(f.relative_to(PKG)), set())
                bad += [f"{f.relative_to(PKG)}:{node.lineno} {n}" for n in names
                        if n.split(".")[0] not in here]
    assert not bad, bad


def test_the_old_flat_paths_still_import_with_a_warning():
    import importlib
    import sys

    sys.modules.pop("cmm_dae.events", None)
    with pytest.warns(DeprecationWarning, match="cmm_dae.events is now cmm_dae.hybrid.policy"):
        old = importlib.import_module("cmm_dae.events")
    from cmm_dae.hybrid import policy

    assert old is policy


def test_an_old_path_leaves_the_api_function_of_its_name():
    """Importing ``cmm_dae.sweep``, ``.structure`` or ``.design`` (old module paths whose
    names are also API functions) put the module in the function's place: the next
    ``cd.sweep(...)`` was "'module' object is not callable". The module still imports."""
    import importlib
    import sys
    import types

    import cmm_dae as cd
    from cmm_dae.simulation import structure
    from cmm_dae.studies import design, sweep

    for name, new in (("sweep", sweep), ("structure", structure), ("design", design)):
        sys.modules.pop(f"cmm_dae.{name}", None)
        with pytest.warns(DeprecationWarning, match=f"cmm_dae.{name} is now"):
            old = importlib.import_module(f"cmm_dae.{name}")
        assert old is new
        assert callable(getattr(cd, name)) and not isinstance(getattr(cd, name),
                                                               types.ModuleType)
        assert getattr(cd, name) is getattr(new, name)


def test_no_module_over_400_lines():
    over = {str(f.relative_to(PKG)) for f, _ in _modules()
            if len(f.read_text().splitlines()) > 400}
    assert not over, sorted(over)


def test_no_function_over_100_lines():
    """Functions a reader can hold: none of the package's over 100 lines (docstring and
    nested functions included)."""
    import ast

    over = [f"{f.relative_to(PKG)}:{node.lineno} {node.name} "
            f"({node.end_lineno - node.lineno + 1} lines)"
            for f, _ in _modules() for node in ast.walk(ast.parse(f.read_text()))
            if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef)
            and node.end_lineno - node.lineno + 1 > 100]
    assert not over, over


def test_api_reference_lists_exactly_what_the_package_exports():
    import re

    import cmm_dae

    doc = (Path(__file__).resolve().parent.parent / "docs" / "api.md").read_text()
    names = [n for block in re.findall(r"<!-- generated: api ([^>]*?) -->", doc)
             for n in block.split()]
    top = [n.split(".", 1)[1] for n in names if n.count(".") == 1 and n.startswith("cmm_dae.")]
    assert len(top) == len(set(top))
    assert set(top) == set(cmm_dae.__all__)


def test_events_are_built_by_keyword_with_a_typed_kind():
    import cmm_dae as cd

    with pytest.raises(TypeError):
        cd.Event(0.0, "lock", "E", "upper", 0, 1)  # positional: refused
    res = cd.run_dae(cd.load(cd.example("double_folded")), 10.0)
    assert [e.kind for e in res.events] == [cd.EventKind.LIMIT, cd.EventKind.RELEASE]
    assert all(isinstance(e.kind, cd.EventKind) for e in res.events)
    assert res.events[0].kind == "limit"  # equal to the plain string, as saved results are
