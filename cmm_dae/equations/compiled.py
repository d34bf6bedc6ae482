"""Post-processing's and the stepped-over screen's CasADi functions compiled to C, with a
run's compiled segment.

A Result's series and the screen for singular positions come from functions mapped over
every sample (:meth:`~cmm_dae.equations.model.Model.mapped`): the joints' forces and the
drivers' efforts (:mod:`.outputs`), the Schur complements of the KKT systems and the
accelerations (:func:`.kkt.schur_functions`), the coordinates, elements, loads and drift
(:func:`.outputs.series_function`), the Gram matrices of the screen
(:func:`.kinematics.gram_function`); and the model's single-state evaluators (constraints,
joint coordinates, KKT parts, event parts). CasADi's virtual machine evaluates them a
node at a time; generated C does the same operations in the same order, so the numbers
agree to round-off. Where a run uses the compiled segment (``compiled=True``, or
``"auto"`` with the build cached), these functions are compiled into one more cached
library and put in place of the model's own (:func:`use_compiled`).
"""

from __future__ import annotations

import math
import subprocess

import casadi as ca
import numpy as np

from ..core.memo import once
from . import banded, kinematics, kkt, outputs
from .codegen import Buffered, NotBuiltError, build_library, function_key
from .lifting import external, lift, wrap
from .model import Model

__all__ = ["BANDED", "DENSE", "MAPPED", "OUTPUTS_BUDGET", "SINGLE", "instructions",
           "use_compiled"]

#: The model's attributes so replaced, and the names of their CasADi functions.
MAPPED = {"outputs_fn": "outputs", "series_fn": "series", "gram_fn": "gram",
          "schur_fn": "schur", "acc_fn": "acc", "post_kkt_fn": "post_kkt",
          "kkt_nz_fn": "kkt_nz", "phi_q_nz_fn": "phi_q_nz", "free_fn": "free_rows",
          "con_nz_fn": "con_nz"}
#: Those compiled for a mechanism that is not banded (where it has them).
DENSE = ("outputs_fn", "series_fn", "gram_fn", "schur_fn", "acc_fn", "post_kkt_fn")
#: Those compiled for a banded one (:func:`~.banded.for_model`), whose post-processing and
#: screen work from Phi_q's nonzeros (A02 with 32 loops: 11,400 instructions; its dense
#: Schur complement, Gram matrix and single-state evaluators would be 250,000).
BANDED = ("outputs_fn", "series_fn", "kkt_nz_fn", "phi_q_nz_fn", "free_fn", "con_nz_fn")
#: The model's single-state evaluators (:class:`~.codegen.Buffered`) so replaced (not on
#: a banded mechanism).
SINGLE = ("_phi", "_coord", "_cvel", "_post", "_kin", "_rates_jac", "_kkt_parts", "_free",
          "event_parts")


def _functions(model: Model) -> dict[str, ca.Function]:
    """The functions of :data:`MAPPED` that ``model`` has, built where not yet."""
    outputs.function(model)
    outputs.series_function(model)
    if banded.for_model(model) is not None:
        banded.kkt_nz_function(model)
        banded.constraints_nz_function(model)
        return {attr: getattr(model, attr) for attr in BANDED}
    kinematics.gram_function(model)
    if model.m and np.all(model.mass > 0.0):  # (the Schur complement needs every mass)
        kkt.schur_functions(model)
    return {attr: getattr(model, attr) for attr in DENSE
            if getattr(model, attr, None) is not None}


def _singles(model: Model) -> dict[str, ca.Function]:
    """The single-state evaluators of :data:`SINGLE` compiled for ``model`` (none for a
    banded one)."""
    if banded.for_model(model) is not None:
        return {}
    return {attr: getattr(model, attr).fn for attr in SINGLE}


#: Most CasADi instructions compiled into the library of a model's post-processing and
#: screen functions: gcc's time grows faster than their count (0.75 s for the double-folded
#: mechanism's 3,600, 2.8 s for the nipper's 10,100, 13.5 s for A02 with 8 loops' 28,600,
#: 359 s with 32 loops); a larger model keeps them on CasADi's virtual machine.
OUTPUTS_BUDGET = 12_000


def instructions(model: Model) -> float:
    """CasADi instructions of the functions :func:`use_compiled` compiles (counted once
    per model, before they are replaced by compiled ones, which cannot count them); inf
    for more than :data:`~.kkt.LDL_ROWS` constraint rows unless the mechanism is banded
    (:data:`BANDED`), without building them (their Schur complement and Gram matrix alone
    are m^2 outputs)."""
    if model.m > kkt.LDL_ROWS and banded.for_model(model) is None:
        return math.inf

    def count() -> int:
        every = [*_functions(model.shared).values(), *_singles(model.shared).values()]
        return sum(f.n_instructions() for f in every)

    # (counted on the structure's model: a variant holds its compiled functions, which
    # cannot count them)
    return once(model.shared, ("outputs instructions",), count)


def use_compiled(model: Model, build: bool = True) -> bool:
    """Put compiled versions of the functions of :data:`MAPPED` in place of ``model``'s
    own, from the cache (``build=False``: only if built already) or built now; False,
    with the model unchanged, where they are not built or cannot be, or are more than
    :data:`OUTPUTS_BUDGET` instructions."""
    if getattr(model, "outputs_compiled", False):
        return True
    if model.shared is not model:  # a variant: compiled once for its structure's model
        if not use_compiled(model.shared, build):
            return False
        for attr in (*MAPPED, *SINGLE, "outputs_compiled"):
            if hasattr(model.shared, attr):
                setattr(model, attr, getattr(model.shared, attr))
        model._maps = model.shared._maps
        return True
    if instructions(model) > OUTPUTS_BUDGET:
        return False
    funcs, singles = _functions(model), _singles(model)
    # their numbers as inputs (:mod:`.lifting`): one library per mechanism structure
    lifted = once(model, ("outputs lifted",), lambda: {
        attr: lift(f) for attr, f in [*funcs.items(), *singles.items()]})
    every = [x.fn for x in lifted.values()]
    try:
        lib = build_library(function_key(every), None, every, build=build)
    except NotBuiltError:
        return False
    except (OSError, subprocess.SubprocessError, RuntimeError):
        return False  # the model's own functions give the same numbers
    for attr, x in lifted.items():
        ext = external(x.fn.name(), str(lib))
        setattr(model, attr, Buffered(ext, fixed=x.values) if attr in singles
                else wrap(ext, x.values))
    # the maps built on the virtual machine's functions go (they are built anew on use)
    model.forget_maps(MAPPED)
    model.outputs_compiled = True
    return True
