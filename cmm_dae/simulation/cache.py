"""The equations of the mechanisms run last, reused when the same mechanism runs again.

Building a model (the symbolic equations, their CasADi functions, the maps that
post-processing evaluates them through, the redundancy and rank checks of its start) costs
more than a short run: on a hanging chain of 32 four-bar loops a 0.01-s run took 43 % of
the time of a 2-s run with the model built each time, 11 % with it built once. A run of
``run_dae(mech)`` without ``model=`` therefore reuses the model of the last few
mechanisms it ran, found by identity (the same ``Mechanism`` object) and checked by
content (its ``repr``, so that a mechanism changed in place is built anew).
"""

from __future__ import annotations

import hashlib
import weakref
from collections import OrderedDict
from collections.abc import Callable

from ..description.mechanism import Mechanism
from ..equations.model import Model

__all__ = ["MODELS_KEPT", "clear", "model_of"]

#: How many mechanisms' models are kept (the least recently run goes first).
MODELS_KEPT = 4

_models: OrderedDict[int, tuple[weakref.ref, str, Model]] = OrderedDict()


def _signature(mech: Mechanism) -> str:
    return hashlib.sha1(repr(mech).encode(), usedforsecurity=False).hexdigest()


def model_of(mech: Mechanism, build: Callable[[Mechanism], Model]) -> Model:
    """The model of ``mech``: the one built for it before (same object, same content), or
    ``build(mech)``, kept for the next run."""
    key, sig = id(mech), _signature(mech)
    hit = _models.get(key)
    if hit is not None and hit[0]() is mech and hit[1] == sig:
        _models.move_to_end(key)
        return hit[2]
    model = build(mech)
    _models[key] = (weakref.ref(mech), sig, model)
    _models.move_to_end(key)
    while len(_models) > MODELS_KEPT:
        _models.popitem(last=False)
    return model


def clear() -> None:
    """Forget every kept model."""
    _models.clear()
