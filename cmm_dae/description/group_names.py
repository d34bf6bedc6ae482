"""How a group found by the structure analysis is named and classed: the letters of its
joints along the group (R revolute, P prismatic, C contact), a chain from one external
joint to the other or branches around a ternary body, and its class (II for two bodies,
III for four around a ternary body)."""

from __future__ import annotations

from .mechanism import Mechanism

__all__ = ["group_class", "group_name"]


def _letter(mech: Mechanism, j: str) -> str:
    return {"revolute": "R", "prismatic": "P"}.get(mech.joints[j].type, "C")


def _other(mech: Mechanism, joint: str, body: str) -> str:
    j = mech.joints[joint]
    return j.second_body if j.first_body == body else j.first_body


def _touches(mech: Mechanism, joint: str, body: str) -> bool:
    return body in (mech.joints[joint].first_body, mech.joints[joint].second_body)


def _walk(mech: Mechanism, adj: dict[str, list[str]], degree: dict[str, int], body: str,
          seq: list[str]) -> tuple[list[str], str]:
    """Follow internal joints from ``body`` (``seq`` holds the joints taken so far) until a
    free end or a body with more than two internal joints; returns (joints, last body)."""
    seen = set(seq)
    while True:
        nxt = [k for k in adj[body] if k not in seen]
        if not nxt or degree[body] > 2:
            return seq, body
        seq.append(nxt[0])
        seen.add(nxt[0])
        body = _other(mech, nxt[0], body)


def group_name(mech: Mechanism, bodies: set[str], internal: list[str], external: list[str]
                ) -> str:
    """Letters along the group: a chain from one external joint to the other, or branches
    (external then internal joint) around a ternary body."""
    adj: dict[str, list[str]] = {b: [] for b in bodies}
    for j in internal:
        adj[mech.joints[j].first_body].append(j)
        adj[mech.joints[j].second_body].append(j)
    degree = {b: len(adj[b]) for b in bodies}
    if max(degree.values(), default=0) <= 2:  # chain
        if not external:
            return "".join(_letter(mech, j) for j in internal)
        start = external[0]
        body = next(x for x in bodies if _touches(mech, start, x))
        seq, _ = _walk(mech, adj, degree, body, [start])
        seq += [j for j in external if j not in seq][:1]
        return "".join(_letter(mech, j) for j in seq)
    hub = max(bodies, key=lambda x: degree[x])
    branches = []
    for j in adj[hub]:  # each branch: its external joint(s), then inward to the hub
        seq, end = _walk(mech, adj, degree, _other(mech, j, hub), [j])
        ext = [e for e in external if _touches(mech, e, end)]
        branches.append("".join(_letter(mech, e) for e in ext + seq[::-1]))
    hub_ext = [e for e in external if _touches(mech, e, hub)]
    if hub_ext:
        branches.append("".join(_letter(mech, e) for e in hub_ext))
    return "-".join(branches)


def group_class(n_bodies: int, degrees: list[int]) -> int:
    if n_bodies <= 1:
        return 1
    if n_bodies == 2:
        return 2
    if n_bodies == 4 and max(degrees, default=0) >= 3:
        return 3
    return n_bodies
