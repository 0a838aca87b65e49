"""Suffixes that wrap a policy: `NAME+route`, `NAME+shield`, `NAME+route+shield` (in that order).

- `+route` (`envs.policies.routed`): the policy heads for the global route's subgoal through the walls instead of the
  goal (in `view.goal` and in the observation's goal features);
- `+shield` (`envs.policies.shielded`): every decision is checked by the MPC's safety shield before the env applies it.

The MPC policies (`mpc-*`) take neither: their planner routes and shields already. The wrapped policy's name, flags,
weight files and wall rays are the base name's; the full name is what the records and leaderboards show.
"""

from __future__ import annotations

ROUTE_SUFFIX = "+route"
SHIELD_SUFFIX = "+shield"
SUFFIXES = (ROUTE_SUFFIX, SHIELD_SUFFIX)  # innermost first: NAME+route+shield routes, then shields
SELF_WRAPPED = ("mpc-gpgraph", "mpc-oracle", "mpc-oracle-paths", "mpc-oracle-groups", "mpc-cv", "mpc-none")


def split_wrappers(name: str) -> tuple[str, tuple[str, ...]]:
    """(the base policy's name, the suffixes in `name`, innermost first). ValueError for a suffix with no name
    before it, repeated or out of order, or on a policy whose planner routes and shields already."""
    base, found = name, []
    for suffix in reversed(SUFFIXES):
        if base.endswith(suffix):
            base, found = base[: -len(suffix)], [suffix, *found]
    if not base or any(s in base for s in SUFFIXES):
        raise ValueError(f"policy {name!r}: the suffixes follow one policy name, each at most once, in the order "
                         f"{''.join(SUFFIXES)}")
    if found and base in SELF_WRAPPED:
        raise ValueError(f"policy {name!r}: {base} routes and shields in its planner already "
                         f"({' and '.join(SUFFIXES)} wrap the other policies)")
    return base, tuple(found)


def base_name(name: str) -> str:
    """The policy name without its wrapper suffixes."""
    return split_wrappers(name)[0]
