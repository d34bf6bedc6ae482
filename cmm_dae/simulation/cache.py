"""The equations of the mechanisms run last, reused when the same mechanism runs again.

Building a model (the symbolic equations, their CasADi functions, the maps that
post-processing evaluates them through, the redundancy and rank checks of its start) costs
more than a short run: on a hanging chain of 32 four-bar loops a 0.01-s run took 43 % of
the time of a 2-s run with the model built each time, 11 % with it built once. A run of
``run_dae(mech)`` without ``model=`` therefore reuses the model of the last few
mechanisms it ran, found by identity (the same ``Mechanism`` object) and checked by
content, so that a mechanism changed in place is built anew. A ``Mechanism`` is frozen
and its tables are read-only views of its own copies; what can still change in place are
the mutable values a user handed it (a list for a table of times, say). The check is
the content of those alone, found once per mechanism (the ``repr`` of the whole took
1.4 ms a run of A02 with 32 loops, a sixth of a 0.01-s run).
"""

from __future__ import annotations

import dataclasses
import hashlib
import weakref
from collections import OrderedDict
from collections.abc import Callable
from types import MappingProxyType

import numpy as np

from ..description.mechanism import Mechanism
from ..equations.model import Model
from ..equations.values import structure_key, value_paths, variant
from ..hybrid.start import redundant_base_rows

__all__ = ["MODELS_KEPT", "STRUCTURES_KEPT", "built", "clear", "model_of", "shared_model",
           "structure_of", "without_redundant"]

#: How many mechanisms' models are kept (the least recently run goes first).
MODELS_KEPT = 4

_models: OrderedDict[int, tuple[weakref.ref, str, Model, list]] = OrderedDict()


def _mutable(x, found: list) -> list:
    """The mutable values reachable from ``x`` (lists, dicts, sets, arrays and objects
    that are not frozen dataclasses; the tables' read-only views are walked through)."""
    if isinstance(x, str | bytes | int | float | complex | bool | type(None)):
        return found
    if isinstance(x, tuple | frozenset):
        for y in x:
            _mutable(y, found)
    elif isinstance(x, MappingProxyType):
        for k, y in x.items():
            _mutable(k, found)
            _mutable(y, found)
    elif dataclasses.is_dataclass(x) and x.__dataclass_params__.frozen:
        for f in dataclasses.fields(x):
            _mutable(getattr(x, f.name), found)
    elif not callable(x):  # (a load law's function: compared by identity, as in repr)
        found.append(x)
    return found


def _signature(leaves: list) -> str:
    """The content of a mechanism's mutable values (an array's every byte: its repr
    elides the middle of a long one)."""
    h = hashlib.sha1(usedforsecurity=False)
    for x in leaves:
        if isinstance(x, np.ndarray):
            h.update(f"{x.dtype}{x.shape}".encode())
            h.update(np.ascontiguousarray(x).tobytes())
        else:
            h.update(repr(x).encode())
    return h.hexdigest()


def model_of(mech: Mechanism, build: Callable[[Mechanism], Model]) -> Model:
    """The model of ``mech``: the one built for it before (same object, same content), or
    ``build(mech)``, kept for the next run."""
    key = id(mech)
    hit = _models.get(key)
    if hit is not None and hit[0]() is mech and hit[1] == _signature(hit[3]):
        _models.move_to_end(key)
        return hit[2]
    leaves = _mutable(mech, [])
    model = build(mech)
    _models[key] = (weakref.ref(mech), _signature(leaves), model, leaves)
    _models.move_to_end(key)
    while len(_models) > MODELS_KEPT:
        _models.popitem(last=False)
    return model


#: How many structures' models :func:`shared_model` keeps (the least recently used first
#: out): a sweep's variants share one; a study of a few mechanisms keeps each of theirs.
STRUCTURES_KEPT = 4

_structures: OrderedDict[tuple[str, tuple[int, ...]], Model] = OrderedDict()


def structure_of(mech: Mechanism) -> str:
    """``mech``'s structure key (:func:`~cmm_dae.equations.values.structure_key`)."""
    return structure_key(mech, value_paths(mech))


def shared_model(mech: Mechanism, key: str, drop: tuple[int, ...],
                 build: Callable[[], Model]) -> Model:
    """A model of ``mech`` (structure ``key``, redundant rows ``drop`` left out): a
    :meth:`~cmm_dae.equations.model.Model.variant` of the one built for a mechanism of
    the same structure, or ``build()``, kept for the next."""
    base = _structures.get((key, drop))
    if base is not None:
        _structures.move_to_end((key, drop))
        return base if base.mech is mech else variant(base, mech, key)
    model = build()
    model.structure = key  # (found already: values.structure_of need not again)
    _structures[(key, drop)] = model
    while len(_structures) > STRUCTURES_KEPT:
        _structures.popitem(last=False)
    return model


def clear() -> None:
    """Forget every kept model."""
    _models.clear()
    _structures.clear()


def without_redundant(model: Model) -> Model:
    """The model itself, or, for a redundant constraint set, the equations without the
    dependent rows."""
    drop = redundant_base_rows(model)
    return Model(model.mech, drop=drop) if drop else model


def built(mech: Mechanism) -> Model:
    """A model of ``mech`` (redundant rows left out), as a run uses it: a variant of the
    one of a mechanism of the same structure (:func:`shared_model`), or built."""
    key = structure_of(mech)
    model = shared_model(mech, key, (), lambda: Model(mech))
    drop = redundant_base_rows(model) if model.m > 0 else ()
    if not drop:
        return model
    return shared_model(mech, key, drop, lambda: Model(mech, drop=drop))
