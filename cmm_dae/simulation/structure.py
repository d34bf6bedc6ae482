"""The structure analysis a user asks for (``cd.structure``, ``cmm-dae structure``): the
planar one of :mod:`cmm_dae.description.structure` (Assur groups), or for a spatial
mechanism its mobility from the rank of the constraint Jacobian at the assembled start,
with its redundant rows named (the Bennett linkage's 20 joint rows leave mobility 1
where the count of rows would give -2)."""

from __future__ import annotations

import numpy as np

from ..description.mechanism import Mechanism
from ..description.structure import (  # noqa: F401 (the old path cmm_dae.structure's names)
    MAX_GROUP,
    SEARCH_BUDGET,
    Group,
    Structure,
    configuration_label,
    force_constraint_joints,
    labeller,
)
from ..description.structure import structure as planar_structure
from ..equations import rank
from ..equations.model import Model
from ..hybrid.start import assemble_positions, initial_guess, redundant_base_rows

__all__ = ["structure"]


def structure(mech: Mechanism, *, budget: int = SEARCH_BUDGET) -> Structure:
    """Decompose a planar mechanism into active parts, Assur groups and augmented Assur
    groups; for a spatial one, its mobility and redundant rows.

    Parameters
    ----------
    mech : Mechanism
    budget : int
        Most candidate body sets the planar group search examines.

    Returns
    -------
    Structure
        Printable (``str``) report; a spatial mechanism's has ``redundant`` (the rows
        left out as dependent at the start) and no groups.
    """
    if not mech.spatial:
        return planar_structure(mech, budget=budget)
    model = Model(mech)
    known = {k: v for k, v in mech.initial.joints.items() if k not in mech.drivers}
    q = assemble_positions(model, 0.0, model.params(), known, initial_guess(model))
    drop = redundant_base_rows(model)
    A = np.asarray(model.base_fn(q, 0.0, model.params())).reshape(model.n_base, model.nq)
    rows = [i for i, r in enumerate(model.all_rows[:model.n_base]) if r.kind != "driver"]
    mobility = model.nq - rank.rank(A[rows]) if rows else model.nq
    return Structure(mech.name, int(mobility), tuple(mech.drivers), (),
                     redundant=tuple(f"{model.all_rows[i].kind} {model.all_rows[i].name}"
                                     for i in drop))
