"""Which compiled segment a run uses, and when it is built: ``compiled=True`` builds it
before the run; ``"auto"`` (the default) uses it where it is in the cache, builds it
before the run where the build is short (:data:`AUTO_BUILD_NOW`), and otherwise builds
it in the background once a mechanism's runs in Python took long enough together
(:data:`AUTO_BUILD_AFTER`); ``False`` never. Also the registry of the segments loaded
in this process (:mod:`.csegment` is the segment itself)."""

from __future__ import annotations

import atexit
import os
import subprocess
import threading
import warnings
import weakref

from ..core.errors import CompileNotice
from ..equations import compiled
from ..equations.codegen import NotBuiltError, c_compiler, cache_dir
from ..equations.model import Model
from . import csegment

__all__ = ["AUTO_BUILD_AFTER", "AUTO_BUILD_NOW", "auto_builds", "build_estimate",
           "build_later", "choose", "clear", "for_model"]


#: model -> {sparse: CompiledModel, None (its build failed), _MISSING (not built: "auto"
#: looked) or _BUILDING (a background build runs)}, weak in the model
_models: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()
_MISSING, _BUILDING = "missing", "building"
_warned = _noticed = False
_builds: list[threading.Thread] = []


def clear() -> None:
    """Forget the compiled segments loaded in this process (looked up in the cache again)."""
    _join()
    _models.clear()


def _warn_once(message: str) -> None:
    """Say why the compiled segment is not used, once per process."""
    global _warned
    if not _warned:
        warnings.warn(message, stacklevel=5)
        _warned = True


def _unsupported(model: Model) -> str | None:
    """Why ``model`` runs in Python whatever the machine has, or None."""
    return ("load laws given as Python callables run in Python" if model.callables else
            "friction from the reaction is solved in Python" if model.reacting else None)


def for_model(model: Model, sparse: bool = False) -> csegment.CompiledModel | None:
    """The compiled segment of ``model`` (built on first use, kept with the model), or None
    with a warning (once per process) when it cannot be used: no working C compiler, no
    SUNDIALS libraries from scikit-sundae, load laws given as Python callables, or
    friction from the reaction (its event functions solve a nonlinear KKT system)."""
    why = csegment.available() or _unsupported(model)
    if why is not None:
        _warn_once(f"compiled segment not used ({why}): running the Python path")
        return None
    per_model = _models.setdefault(model.shared, {})
    if not isinstance(per_model.get(sparse), csegment.CompiledModel):
        if per_model.get(sparse) is _BUILDING:
            _join()
        try:
            per_model[sparse] = csegment.CompiledModel(model, sparse)
        except (OSError, subprocess.SubprocessError, RuntimeError) as e:
            warnings.warn(f"compiled segment not used (building this model failed: {e}): "
                          "running the Python path", stacklevel=4)
            per_model[sparse] = None
    return per_model[sparse]


def choose(model: Model, sparse: bool, mode: bool | str) -> csegment.CompiledModel | None:
    """The compiled segment a run of ``model`` uses, by its option ``compiled``: True
    builds it where it can (:func:`for_model`), False never; ``"auto"`` (the default)
    uses it where it is built already (in the cache, by an earlier run or process), else
    builds it before the run where that is short (:data:`AUTO_BUILD_NOW`), else takes
    the Python path (:func:`build_later` builds it once the runs took long enough); the
    Python path, quietly, where the machine has no compiler, for the mechanisms it does
    not cover and where a build fails; with another scikit-sundae than the driver was
    written for, with one warning."""
    if mode is True:
        return for_model(model, sparse)
    if mode is False or _unsupported(model) is not None or csegment._driver_error is not None:
        return None
    if csegment._driver is None:
        try:  # another scikit-sundae: never loaded; said once, as with True
            csegment.check_version()
        except OSError as e:
            csegment._driver_error = str(e)
            _warn_once(f"compiled segment not used ({e})")
            return None
    per_model = _models.setdefault(model.shared, {})
    got = per_model.get(sparse, _MISSING)
    if got is _MISSING:
        try:
            got = per_model[sparse] = csegment.CompiledModel(model, sparse, build=False)
        except NotBuiltError:  # built now where that is short, else Python for now
            got = per_model[sparse] = _MISSING
            if auto_builds() and build_estimate(model) <= AUTO_BUILD_NOW:
                _build(model, sparse)
                got = per_model[sparse]
        except (OSError, subprocess.SubprocessError, RuntimeError):
            got = per_model[sparse] = None  # (another scikit-sundae, a broken library)
    return got if isinstance(got, csegment.CompiledModel) else None


#: compiled="auto" builds a mechanism's segment before its first run where the build is
#: estimated (:func:`build_estimate`) to take at most this (s), once per machine and
#: mechanism, then cached: the shipped models but one (estimated 0.3-3.3 s; the curved
#: slot 5.3 s), A02 with 1 to 32 loops (estimated 0.85, 1.1, 1.9, 3.6 s for 1, 8, 16, 32; the
#: build measured 0.76, 1.6 and 5.5-5.7 s with 8, 16 and 32 loops on a busy machine, where
#: gcc -O2 one library after the other took 3.3, 4.7 and 13.9-14.3 s). Larger ones run in
#: Python until their runs took long enough together (:data:`AUTO_BUILD_AFTER`).
AUTO_BUILD_NOW = 4.0


def auto_builds() -> bool:
    """Whether ``compiled="auto"`` may build: a C compiler is there and the environment
    variable ``CMM_DAE_AUTO_BUILD`` is not ``0`` (set it to use only builds that are
    cached, e.g. on a machine that shares its cache or runs many short processes)."""
    return os.environ.get("CMM_DAE_AUTO_BUILD", "1").strip() != "0" and \
        c_compiler() is not None


#: compiled="auto" builds a segment in the background once the runs of a model in Python
#: in this process took this long (s) and twice the build's estimate (:func:`build_estimate`)
#: together: a long run, or a sweep of short ones (A02 with 8 loops: a 2-s run in 0.1 s).
AUTO_BUILD_AFTER = 2.0
_spent: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()  # model -> s in Python


def build_estimate(model: Model) -> float:
    """Seconds to build ``model``'s compiled segment from its CasADi instructions, gcc -O1
    (measured on a busy 2-core machine, residual and Jacobian: 0.17-0.63 s for
    500-3,500, 1.5 s for 7,000, 3.9 s for 13,900, 3.7 s for 20,700; post-processing's
    library, where built: 0.3-0.9 s up to 3,600, 1.9-2.5 s for 8,800-10,200, 1.6 and 5.4 s
    for A02 with 16 and 32 loops' 5,800 and 11,400). The two libraries compile at once
    where the machine has two cores or more."""
    u, outs = model.ida, compiled.instructions(model)
    seg = 0.1 + 2.5e-4 * (u.res_sx.n_instructions() + u.jac_sparse_fn.n_instructions())
    post = 0.2 + 3e-4 * outs if outs <= compiled.OUTPUTS_BUDGET else 0.0
    return max(seg, post) if (os.cpu_count() or 1) > 1 else seg + post


def build_later(model: Model, sparse: bool, mode: bool | str, used: csegment.CompiledModel | None,
                seconds: float) -> None:
    """After a run of ``seconds`` (wall time) in Python under ``compiled="auto"``: build
    the compiled segment in a background thread once the model's runs took long enough
    together (:data:`AUTO_BUILD_AFTER`), so that the next runs of the mechanism use it;
    said once per process (:class:`~cmm_dae.core.errors.CompileNotice`). The process
    waits for the build at exit, so that the cache never keeps half a build."""
    global _noticed
    if mode != "auto" or used is not None or _unsupported(model) is not None \
            or not auto_builds() or csegment._driver_error is not None:
        return
    per_model = _models.setdefault(model.shared, {})
    if per_model.get(sparse, _MISSING) is not _MISSING:
        return  # built, building or failed
    key = model.shared
    est, _spent[key] = build_estimate(model), _spent.get(key, 0.0) + seconds
    if _spent[key] < max(AUTO_BUILD_AFTER, 2.0 * est):
        return
    per_model[sparse] = _BUILDING
    if not _noticed:
        warnings.warn(f"compiled=\"auto\": building the compiled segment of "
                      f"{model.mech.name!r} in the background (about {est:.1f} s; cached "
                      f"in {cache_dir()}); later runs of it use it (never: compiled=False, "
                      "or --no-compiled)", CompileNotice, stacklevel=6)
        _noticed = True
    if not _builds:
        atexit.register(_join)
    thread = threading.Thread(target=_build, args=(model, sparse), daemon=True,
                              name="cmm_dae compiled segment")
    _builds.append(thread)
    thread.start()


def _build(model: Model, sparse: bool) -> None:
    per_model = _models.setdefault(model.shared, {})
    try:
        per_model[sparse] = csegment.CompiledModel(model, sparse)
    except (OSError, subprocess.SubprocessError, RuntimeError):
        per_model[sparse] = None  # a failed background build: the Python path, quietly


def _join() -> None:
    """Wait for the background builds (at exit, and before a build of the same model)."""
    for thread in list(_builds):
        thread.join()
