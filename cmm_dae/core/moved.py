"""The module paths of cmm_dae before 0.3, when its 52 modules lay in one folder: each old
path (``cmm_dae.events``, ``cmm_dae.ida``, ...) still imports, as the module that now
holds its code, with a :class:`DeprecationWarning` naming the new path. Kept for one
release (listed in the CHANGELOG); the five old modules whose names are now sub-packages
(``hybrid``, ``singular``, ``sensitivity``, ``studies``, ``report``) re-export their names
from those packages instead."""

from __future__ import annotations

import importlib
import importlib.abc
import importlib.util
import sys
import types
import warnings

#: old module (under cmm_dae) -> the module that holds its code now
MOVED = {
    "errors": "core.errors", "progress": "core.progress",
    "mechanism": "description.mechanism", "checks": "description.checks",
    "schema": "description.schema", "loader": "description.loader",
    "params": "description.params", "writer": "description.writer",
    "library": "description.library", "structure": "simulation.structure",
    "iftomm": "description.iftomm",
    "equations": "equations.model", "laws": "equations.laws", "buffers": "equations.codegen",
    "schur": "equations.kkt", "kinematics": "equations.kinematics",
    "unknowns": "equations.unknowns",
    "events": "hybrid.policy", "zones": "hybrid.zones", "assembly": "hybrid.start",
    "equilibrium": "hybrid.equilibrium",
    "gauss": "singular.gauss", "branches": "singular.branches",
    "singular_instant": "singular.instant",
    "integrator": "integrators.contract", "ida": "integrators.ida",
    "csegment": "integrators.csegment", "iterative": "integrators.iterative",
    "tolerances": "integrators.tolerances",
    "runner": "simulation.runner", "crossing": "simulation.crossing",
    "passage": "simulation.passage",
    "result": "results.result", "post": "results.post", "audit": "results.audit",
    "storage": "results.storage", "export": "results.export",
    "sensitivity_model": "sensitivity.model", "sensitivity_pass": "sensitivity.replay",
    "sensitivity_crossing": "sensitivity.crossing",
    "sweep": "studies.sweep", "design": "studies.design", "studyfile": "studies.studyfile",
    "targets": "studies.targets", "bench": "studies.bench",
    "plots": "report.plots", "animation": "report.animation",
}


class _Alias(importlib.abc.Loader):
    def __init__(self, new: str):
        self.new = new

    def create_module(self, spec):
        warnings.warn(f"{spec.name} is now {self.new}; the old path goes in the next "
                      "release", DeprecationWarning, stacklevel=2)
        return importlib.import_module(self.new)

    def exec_module(self, module) -> None:  # the module is the new one, already run
        pass


class _Finder(importlib.abc.MetaPathFinder):
    """Finds ``cmm_dae.<old>`` as the module of :data:`MOVED`."""

    def find_spec(self, fullname, path=None, target=None):
        pkg, _, old = fullname.rpartition(".")
        if pkg != "cmm_dae" or old not in MOVED:
            return None
        return importlib.util.spec_from_loader(fullname, _Alias(f"cmm_dae.{MOVED[old]}"))


class Package(types.ModuleType):
    """The class of the ``cmm_dae`` module: importing an old path whose name is also a
    function of the API (``cmm_dae.sweep``, ``.structure``, ``.design``) does not put the
    module in that function's place (Python's import sets the parent's attribute after
    loading a submodule; the next ``cd.sweep(...)`` was "'module' object is not
    callable")."""

    def __setattr__(self, name: str, value) -> None:
        old = self.__dict__.get(name)
        if (name in MOVED and isinstance(value, types.ModuleType) and old is not None
                and not isinstance(old, types.ModuleType)):
            return
        super().__setattr__(name, value)


def install(package: str = "cmm_dae") -> None:
    """Put the finder of old paths on ``sys.meta_path`` (once) and guard ``package``'s
    API names (:class:`Package`)."""
    if not any(isinstance(f, _Finder) for f in sys.meta_path):
        sys.meta_path.append(_Finder())
    sys.modules[package].__class__ = Package
