"""The learned cut planner: torch environment, actor-critic networks, DDPG from demonstrations.

Only this package imports torch. Modules: :mod:`~slicerecon.policy.env`
(batched cut environment over the rules of :mod:`slicerecon.partition`),
:mod:`~slicerecon.policy.reward` (the reward's part surface, numpy) and
:mod:`~slicerecon.policy.surrogate` (its batched torch surrogate),
:mod:`~slicerecon.policy.networks`, :mod:`~slicerecon.policy.buffers`,
:mod:`~slicerecon.policy.ddpg`, :mod:`~slicerecon.policy.train` (``TrainConfig``,
``train``), :mod:`~slicerecon.policy.weights` and :mod:`~slicerecon.policy.planner`
(``plan_policy``, the ``"policy"`` planner). See ``docs/policy.md``.

The ``"policy"`` entry of :data:`slicerecon.partition.planner.PLANNERS` names
:func:`slicerecon.policy.planner.plan_policy`; torch is imported when that
planner first runs, not when this package is imported.
"""
