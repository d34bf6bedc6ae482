"""Structure analysis: mobility, active parts, Assur groups and augmented Assur groups.

The mechanism is split the way the paper builds it (section 2): the frame, the active parts
(bodies driven directly from an already known body), then, one after the other, the
smallest sets of remaining bodies that are 0-DOF once their joints to the known bodies are
in place (Assur groups) or 1-DOF with a metamorphic joint whose lock makes them 0-DOF
(augmented Assur groups). A metamorphic joint is internal when both its bodies belong to the
group, external when one of them is a known body; locking it gives the *internal* or
*external collision configuration* of the paper. A joint held on its stop by a preloaded
spring (force constraint) is not a collision: the paper counts that configuration as
non-collision.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from dataclasses import dataclass, field

from .group_names import group_class, group_name
from .mechanism import GROUND, Mechanism

#: Most candidate body sets the group search examines for one mechanism. The search walks
#: connected sets of bodies, smallest first, which is polynomial for the small groups of
#: real mechanisms; past this budget the bodies left are reported as not resolved (and
#: configurations get plain labels) instead of the search growing without bound.
SEARCH_BUDGET = 20_000
#: Largest group looked for, in bodies after welding preloaded joints (class II groups have
#: 2 bodies, class III 4; the paper's augmented groups at most 5).
MAX_GROUP = 8


@dataclass(frozen=True)
class Group:
    """One Assur group (or augmented Assur group).

    Attributes
    ----------
    name : str
        Joint letters (R, P) external-internal-external along the group; branches of a
        class III group are separated by '-'.
    cls : int
        Assur class (2, 3, ...); for an augmented group, the class once a metamorphic joint
        locks.
    bodies : tuple[str, ...]
    internal, external : tuple[str, ...]
        Joint names inside the group / joining it to known bodies.
    augmented : bool
        1-DOF group that is 0-DOF only with one of its metamorphic joints locked.
    metamorphic : tuple[str, ...]
        Joints of the group with limits.
    """

    name: str
    cls: int
    bodies: tuple[str, ...]
    internal: tuple[str, ...]
    external: tuple[str, ...]
    augmented: bool = False
    metamorphic: tuple[str, ...] = ()


@dataclass(frozen=True)
class Structure:
    """Structure of a mechanism: ``mobility`` (Grübler, drivers removed), ``active``
    (driven bodies) and ``groups`` in the order they attach; ``unresolved`` lists bodies
    no group could take (a mechanism that is not built from Assur groups, or one whose
    groups lie beyond the search's budget); ``examined`` counts the candidate body sets
    the search looked at."""

    mechanism: str
    mobility: int
    active: tuple[str, ...]
    groups: tuple[Group, ...]
    unresolved: tuple[str, ...] = field(default=())
    force_constraints: tuple[str, ...] = ()
    examined: int = 0
    #: a spatial mechanism's rows found redundant at its start ("joint J1", ...), whose
    #: mobility is the constraint Jacobian's rank deficit (no Assur groups searched)
    redundant: tuple[str, ...] | None = None

    def group_of(self, joint: str) -> Group | None:
        for g in self.groups:
            if joint in g.internal or joint in g.external:
                return g
        return None

    def __str__(self) -> str:
        if self.redundant is not None:  # a spatial mechanism (simulation.structure)
            return "\n".join([
                f"Structure of '{self.mechanism}' (spatial)",
                f"  mobility (rank of the constraint Jacobian at the start, drivers "
                f"removed): {self.mobility}",
                f"  redundant rows: {', '.join(self.redundant) or 'none'}"
                + " (their reactions are shared at minimum norm)" * bool(self.redundant),
                f"  driven joints: {', '.join(self.active) or 'none'}",
                "  Assur groups: not searched in space; configurations are named by "
                "their locked joints"])
        lines = [f"Structure of '{self.mechanism}'",
                 f"  mobility (Grübler, drivers removed): {self.mobility}",
                 f"  active parts: {', '.join(self.active) or 'none'}"]
        for i, g in enumerate(self.groups, 1):
            kind = "augmented Assur group" if g.augmented else "Assur group"
            cls = ("single link, welded to a known body when locked" if g.cls <= 1 else
                   f"class {'I' * g.cls if g.cls <= 3 else g.cls}")
            lines.append(f"  {i}. {kind} {g.name} ({cls}): bodies {', '.join(g.bodies)}")
            lines.append(f"     internal joints: {', '.join(g.internal) or '-'}; "
                         f"external joints: {', '.join(g.external) or '-'}")
            if g.metamorphic:
                parts = []
                for j in g.metamorphic:
                    where = "internal" if j in g.internal else "external"
                    how = "force constraint" if j in self.force_constraints else \
                        "geometric constraint"
                    parts.append(f"{j} ({where}, {how})")
                lines.append(f"     metamorphic joints: {', '.join(parts)}")
        if self.unresolved:
            lines.append(f"  not resolved into groups: {', '.join(self.unresolved)}")
        return "\n".join(lines)


def force_constraint_joints(mech: Mechanism) -> dict[str, str]:
    """Joints whose spring rest lies beyond a limit: joint -> the side it is pressed onto."""
    out = {}
    for name, j in mech.joints.items():
        if j.limits is None or j.spring is None:
            continue
        if j.limits.lower is not None and j.spring.rest < j.limits.lower:
            out[name] = "lower"
        elif j.limits.upper is not None and j.spring.rest > j.limits.upper:
            out[name] = "upper"
    return out


def _cost(mech: Mechanism, joints) -> int:
    """Degrees of freedom the joints take: 2 a lower pair, 1 a contact (a higher pair,
    counted as touching)."""
    return sum(1 if mech.joints[j].type == "contact" else 2 for j in joints)


def _merge(mech: Mechanism, locked: set[str]) -> dict[str, str]:
    """Body -> representative after welding the locked joints (ground absorbs)."""
    rep = {b: b for b in mech.bodies}
    rep[GROUND] = GROUND

    def find(x):
        while rep[x] != x:
            x = rep[x]
        return x

    for j in locked:
        a, b = find(mech.joints[j].first_body), find(mech.joints[j].second_body)
        if a != b:
            if b == GROUND:
                a, b = b, a
            rep[b] = a
    return {b: find(b) for b in rep}


def _connected_sets(units: list[str], neighbours: dict[str, set[str]], budget: int
                    ) -> Iterator[tuple[str, ...]]:
    """Connected sets of units, by size, each size in the order of ``units`` (the order
    ``itertools.combinations`` would give, without the sets that are not connected); no
    more than about ``budget`` of them are ever built."""
    order = {u: i for i, u in enumerate(units)}
    level = {frozenset([u]) for u in units}
    size = 1
    while level and len(level) <= budget and size <= MAX_GROUP:
        budget -= len(level)
        size += 1
        yield from (tuple(sorted(s, key=order.__getitem__))
                    for s in sorted(level, key=lambda s: sorted(order[u] for u in s)))
        level = {s | {n} for s in level for u in s for n in neighbours[u]
                 if n not in s and n in order}


def structure(mech: Mechanism, *, budget: int = SEARCH_BUDGET) -> Structure:
    """Decompose a mechanism into active parts, Assur groups and augmented Assur groups.

    Parameters
    ----------
    mech : Mechanism
    budget : int
        Most candidate body sets to examine; bodies no group took within it are listed
        in ``Structure.unresolved``.

    Returns
    -------
    Structure
        Printable (``str``) report.
    """
    mobility = 3 * len(mech.bodies) - _cost(mech, mech.joints) - len(mech.gears)
    search = _Search(mech, budget)
    groups: list[Group] = []
    while search.remaining:
        g = search.find(0) or search.find(1) or search.find(1, single=True)
        if g is None:
            break
        groups.append(g)
        search.known.update(g.bodies)
        search.remaining = [u for u in search.remaining
                            if not search.units[u] <= search.known]
    order = list(mech.bodies).index
    left = [b for u in search.remaining for b in sorted(search.units[u], key=order)]
    return Structure(mech.name, mobility, tuple(search.active), tuple(groups), tuple(left),
                     tuple(search.welded), budget - max(search.budget, 0))


class _Search:
    """The state of one structure analysis: the known bodies (the frame, then the active
    parts, then each group found), the units left (bodies welded by preloaded joints count
    as one) and what is left of the search budget."""

    def __init__(self, mech: Mechanism, budget: int):
        self.mech, self.budget = mech, budget
        joints = mech.joints
        self.metamorphic = set(mech.limited_joints)
        self.known = {GROUND}
        self.active: list[str] = []
        changed = True
        while changed:  # bodies driven from a known body are active parts
            changed = False
            for d in mech.drivers:
                j = joints[d]
                for a, b in ((j.first_body, j.second_body), (j.second_body, j.first_body)):
                    if a in self.known and b not in self.known and b != GROUND:
                        self.known.add(b)
                        self.active.append(b)
                        changed = True
        # Joints held on a stop by a preloaded spring weld their two bodies in the natural
        # state of the mechanism (the paper: "5 and 6 combined into one component").
        self.welded = force_constraint_joints(mech)
        self.rep = _merge(mech, set(self.welded))
        self.units: dict[str, set[str]] = {}
        for b in mech.bodies:
            if self.rep[b] != GROUND and b not in self.known:
                self.units.setdefault(self.rep[b], set()).add(b)
        self.remaining = list(self.units)
        self.at: dict[str, list[str]] = {}  # body -> its joints (drivers' left out)
        for n, j in joints.items():
            if n not in mech.drivers:
                for b in {j.first_body, j.second_body}:
                    self.at.setdefault(b, []).append(n)
        self.neighbours: dict[str, set[str]] = {u: set() for u in self.units}
        for j in joints.values():
            a, b = self.rep.get(j.first_body), self.rep.get(j.second_body)
            if a in self.neighbours and b in self.neighbours and a != b:
                self.neighbours[a].add(b)
                self.neighbours[b].add(a)
        self.jorder = {n: i for i, n in enumerate(joints)}

    def joints_of(self, S: set[str]) -> tuple[list[str], list[str]]:
        """The joints inside the body set S and those joining it to known bodies."""
        internal, external = [], []
        for n in sorted({n for b in S for n in self.at.get(b, [])},
                        key=self.jorder.__getitem__):
            j = self.mech.joints[n]
            a, b = j.first_body, j.second_body
            if a in S and b in S:
                internal.append(n)
            elif (a in S and b in self.known) or (b in S and a in self.known):
                external.append(n)
        return internal, external

    def connected(self, S: set[str], internal: list[str]) -> bool:
        """Whether the internal joints connect all of S."""
        start = next(iter(S))
        seen, stack = {start}, [start]
        while stack:
            x = stack.pop()
            for n in internal:
                j = self.mech.joints[n]
                for a, b in ((j.first_body, j.second_body), (j.second_body, j.first_body)):
                    if a == x and b not in seen:
                        seen.add(b)
                        stack.append(b)
        return seen == S

    def find(self, target: int, single: bool = False) -> Group | None:
        """Smallest group of the remaining units with ``target`` DOF; an augmented group
        must leave at least two bodies once locked (else it is a link welded to a known
        body), unless ``single`` allows that as a last resort."""
        mech, joints, welded, rep = self.mech, self.mech.joints, self.welded, self.rep
        for combo in _connected_sets(self.remaining, self.neighbours, self.budget):
            self.budget -= 1
            if self.budget < 0:
                return None
            S = set().union(*(self.units[u] for u in combo))
            internal, external = self.joints_of(S)
            if not self.connected(S, internal):
                continue
            live = [j for j in internal if j not in welded]
            f = 3 * len(combo) - _cost(mech, live + list(external))
            meta = tuple(j for j in internal + external if j in self.metamorphic)
            if f != target or (target == 1 and not [m for m in meta if m not in welded]):
                continue
            name = group_name(mech, S, internal, external)
            deg = [sum(rep[b] == u for j in live for b in (joints[j].first_body,
                                                           joints[j].second_body))
                   for u in combo]
            if target == 1:  # class once one (geometric) metamorphic joint locks
                lock = next(m for m in meta if m not in welded)
                rep2 = _merge(mech, set(welded) | {lock})
                n_locked = len({rep2[b] for b in S} - {GROUND})
                if n_locked < 2 and not single:
                    continue
                cls = group_class(n_locked, deg)
            else:
                cls = group_class(len(combo), deg)
            augmented = target == 1 or any(m in welded for m in meta)
            return Group(name, cls, tuple(sorted(S, key=list(mech.bodies).index)),
                         tuple(internal), tuple(external), augmented, meta)
        return None


def configuration_label(st: Structure | None, locked: dict[str, str],
                        force: dict[str, str]) -> str:
    """The paper's name of a configuration: non-collision, internal/external collision.

    Without a structure (``st`` None), or for a joint whose group was not found, the label
    is plain: "collision (joint E)" without internal/external."""
    parts = []
    for j in sorted(locked):
        if force.get(j) == locked[j]:
            continue  # held by its preloaded spring: a force constraint, not a collision
        if locked[j] == "stick":
            parts.append(f"stuck (joint {j})")  # held by friction, not by a stop
            continue
        g = st.group_of(j) if st is not None else None
        if g is None:
            parts.append(f"collision (joint {j})")
            continue
        where = "internal" if j in g.internal else "external"
        parts.append(f"{where} collision (joint {j})")
    return ", ".join(parts) if parts else "non-collision"


def labeller(mech: Mechanism, *, budget: int = SEARCH_BUDGET, mobility: int | None = None
             ) -> Callable[[dict[str, str]], tuple[str, int]]:
    """A function giving (label, mobility) of a configuration from its locked joints.

    The structure analysis runs on the first label that needs it (a geometric lock), with
    a bounded search, so labels never cost more than a small fixed budget. ``mobility``:
    the unlocked mechanism's, where the caller has it from the constraint Jacobian's rank
    (a spatial mechanism's, whose Assur groups are not searched); else counted from the
    joints' rows."""
    force = force_constraint_joints(mech)
    # a unilateral contact holds no row until it lands (a lock, as a stop's)
    if mobility is None:
        mobility = 3 * len(mech.bodies) - sum(j.rows for j in mech.joints.values()) \
            - len(mech.gears)
    cache: list[Structure] = []

    def label(locked: dict[str, str]) -> tuple[str, int]:
        if not cache and not mech.spatial and any(force.get(j) != s and s != "stick"
                                                  for j, s in locked.items()):
            cache.append(structure(mech, budget=budget))
        return configuration_label(cache[0] if cache else None, locked, force), \
            mobility - len(locked)

    return label
