"""Structure analysis: mobility, active parts, Assur groups, configuration labels."""

from __future__ import annotations

from collections.abc import Callable

from .mechanism import Mechanism


def labeller(mech: Mechanism) -> Callable[[dict[str, str]], tuple[str, int]]:
    """A function giving (label, mobility) of a configuration from its locked joints."""
    nb, nj = len(mech.bodies), len(mech.joints)

    def label(locked: dict[str, str]) -> tuple[str, int]:
        dof = 3 * nb - 2 * nj - len(locked)
        if not locked:
            return "non-collision", dof
        return "collision (joint " + ", ".join(sorted(locked)) + ")", dof

    return label
