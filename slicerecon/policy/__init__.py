"""The learned cut planner: torch environment, actor-critic networks, DDPG from demonstrations.

Only this package imports torch. Modules: :mod:`~slicerecon.policy.env`
(batched cut environment over the rules of :mod:`slicerecon.partition`),
:mod:`~slicerecon.policy.reward` (the reward's part surface, numpy) and
:mod:`~slicerecon.policy.surrogate` (its batched torch surrogate),
:mod:`~slicerecon.policy.networks`, :mod:`~slicerecon.policy.buffers`,
:mod:`~slicerecon.policy.ddpg`, :mod:`~slicerecon.policy.train` (``TrainConfig``,
``train``), :mod:`~slicerecon.policy.weights` and :mod:`~slicerecon.policy.planner`
(``plan_policy``, the ``"policy"`` planner). See ``docs/policy.md``.

Importing this package registers the ``"policy"`` planner in
:data:`slicerecon.partition.planner.PLANNERS` (the arrow runs policy → partition)
without importing torch; torch is imported when the planner first runs.
"""

from __future__ import annotations

from typing import Any

from ..partition.planner import PlannerEntry, register_planner


def _plan_policy(occupancy: Any, **options: Any) -> Any:
    """The learned planner, imported (with torch) only when it runs."""
    from .planner import plan_policy

    return plan_policy(occupancy, **options)


register_planner(
    PlannerEntry(
        "policy",
        _plan_policy,
        needs_torch=True,
        takes_weights=True,
        summary="a trained actor (docs/policy.md)",
    )
)
