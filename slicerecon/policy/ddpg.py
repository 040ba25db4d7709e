"""DDPG from demonstrations: the update step of the learned planner.

:class:`DDPG` holds the actor ``pi``, the critic ``Q``, their target copies and
optimizers; :meth:`DDPG.update` takes one gradient step on a minibatch from
the demonstration buffer ``R_D`` and one from the agent buffer ``R_A``
(either may be missing) and reads top to bottom:

1. **Critic** (when the RL loss is on): ``y = r + gamma (1 - done) Q'(s', pi'(s'))``,
   ``L_Q = mean (Q(s, a) - y)^2`` over both minibatches.
2. **Actor**: ``L_pi = rl_weight * (-mean Q(s, pi(s))) + logit_penalty * mean(z^2)
   + bc_weight * L_BC`` (``z`` the pre-sigmoid outputs, or a chooser's
   learned scores) with the
   Q-filtered behaviour cloning loss of the paper
   ``L_BC = mean_i ||pi(s_i) - pi^h(s_i)||^2 * 1[Q(s_i, pi^h(s_i)) > Q(s_i, pi(s_i))]``
   over the demonstration rows and (``bc_on_agent``) the agent rows, restricted
   to the states where the heuristic has an action. The paper writes a sum;
   the mean only rescales ``bc_weight``. Without ``q_filter`` (imitation only)
   the indicator is 1. In Phase I (``pretrain=True``) the actor loss is the
   cloning loss alone.
3. **Targets**: a hard copy every ``target_period`` updates, or Polyak
   averaging ``theta' <- tau theta + (1 - tau) theta'`` after every update.
"""

from __future__ import annotations

import copy
from typing import Any

import torch
import torch.nn.functional as F

from ..errors import OptionError
from .buffers import ReplayBatch
from .networks import Actor, Critic, NetConfig, choice_targets
from .observation import Observation

__all__ = ["DDPG", "TARGET_UPDATES"]

TARGET_UPDATES = ("hard", "polyak")


def _cat(batches: list[ReplayBatch]) -> ReplayBatch:
    if len(batches) == 1:
        return batches[0]
    return ReplayBatch(
        Observation.cat([b.obs for b in batches]),
        torch.cat([b.actions for b in batches]),
        torch.cat([b.rewards for b in batches]),
        Observation.cat([b.next_obs for b in batches]),
        torch.cat([b.dones for b in batches]),
        torch.cat([b.expert_actions for b in batches]),
        torch.cat([b.expert_valid for b in batches]),
    )


class DDPG:
    """Actor, critic, targets and optimizers, with the DDPGfD update.

    Parameters
    ----------
    net : NetConfig
        Network sizes.
    device : str or torch.device
    gamma : float
        Discount factor.
    actor_lr, critic_lr : float
        Adam learning rates.
    rl_weight : float
        Weight of the DDPG actor loss ``-Q(s, pi(s))``; 0 turns reinforcement
        learning off (the critic is then not trained).
    bc_weight : float
        Weight of the behaviour-cloning loss; 0 turns it off.
    q_filter : bool
        Apply the paper's Q-filter to the BC loss.
    bc_on_agent : bool
        Also clone the expert on agent samples (the paper does).
    target_update : {"hard", "polyak"}
    target_period : int
        Updates between hard copies.
    tau : float
        Polyak rate.
    logit_penalty : float
        Weight of ``mean(logits^2)`` added to the actor loss with the DDPG
        term: keeps the sigmoid outputs away from saturation, where the
        critic's gradient vanishes and the actor would freeze on a corner of
        the action cube (observed without it).
    bc_choice : bool
        For a chooser: the cloning loss is the cross-entropy of its scores
        with the index of the target among its choices
        (:func:`~slicerecon.policy.networks.choice_targets`) instead of the
        squared distance of the mixed action to the target.
    """

    def __init__(
        self,
        net: NetConfig,
        *,
        device: str | torch.device = "cpu",
        gamma: float = 0.95,
        actor_lr: float = 1e-4,
        critic_lr: float = 1e-3,
        rl_weight: float = 1.0,
        bc_weight: float = 1.0,
        q_filter: bool = True,
        bc_on_agent: bool = True,
        target_update: str = "hard",
        target_period: int = 100,
        tau: float = 0.005,
        logit_penalty: float = 1e-3,
        bc_choice: bool = False,
    ) -> None:
        if target_update not in TARGET_UPDATES:
            raise OptionError(
                f"target_update must be one of {', '.join(TARGET_UPDATES)} (got {target_update!r})"
            )
        if not 0.0 <= gamma <= 1.0:
            raise OptionError(f"gamma must be in [0, 1] (got {gamma})")
        if rl_weight < 0 or bc_weight < 0 or rl_weight + bc_weight == 0:
            raise OptionError("rl_weight and bc_weight must be >= 0, and not both 0")
        if int(target_period) < 1 or not 0.0 < tau <= 1.0:
            raise OptionError("target_period must be >= 1 and tau in (0, 1]")
        self.device = torch.device(device)
        self.net = net
        self.gamma = float(gamma)
        self.rl_weight = float(rl_weight)
        self.bc_weight = float(bc_weight)
        self.q_filter = bool(q_filter)
        self.bc_on_agent = bool(bc_on_agent)
        self.target_update = target_update
        self.target_period = int(target_period)
        self.tau = float(tau)
        self.logit_penalty = float(logit_penalty)
        if bc_choice and not net.candidates:
            raise OptionError("bc_choice needs a chooser (NetConfig.candidates > 0)")
        self.bc_choice = bool(bc_choice)
        self.actor = Actor(net).to(self.device)
        self.critic = Critic(net).to(self.device)
        self.actor_target = copy.deepcopy(self.actor).requires_grad_(False)
        self.critic_target = copy.deepcopy(self.critic).requires_grad_(False)
        self.actor_opt = torch.optim.Adam(self.actor.parameters(), lr=actor_lr)
        self.critic_opt = torch.optim.Adam(self.critic.parameters(), lr=critic_lr)
        self.n_updates = 0

    @property
    def uses_critic(self) -> bool:
        """Whether the critic is trained (RL loss or Q-filter on)."""
        return self.rl_weight > 0 or (self.bc_weight > 0 and self.q_filter)

    @torch.no_grad()
    def act(self, obs: Observation) -> torch.Tensor:
        """Greedy actions ``pi(s)``, Tensor of shape (B, 5)."""
        self.actor.eval()
        out = self.actor(obs.to(self.device))
        self.actor.train()
        return out

    def update(
        self,
        demo: ReplayBatch | None = None,
        agent: ReplayBatch | None = None,
        *,
        pretrain: bool = False,
    ) -> dict[str, float]:
        """One gradient step of critic and actor on the given minibatches.

        With ``pretrain`` (Phase I, demonstrations only) the actor loss is the
        plain cloning loss: the critic has seen expert actions only, so its
        gradient and its Q-filter at other actions would be extrapolation. The
        critic still learns its TD target on the demonstrations.

        Returns
        -------
        dict of str to float
            ``critic_loss``, ``actor_loss``, ``bc_loss``, ``q_mean`` and
            ``q_filter_frac`` (share of BC rows the Q-filter kept); NaN for
            parts that are off.
        """
        parts = [b for b in (demo, agent) if b is not None]
        if not parts:
            raise OptionError("update needs a demonstration or an agent minibatch")
        batch = _cat(parts)
        n_demo = 0 if demo is None else int(demo.actions.shape[0])
        out = {
            "critic_loss": float("nan"),
            "actor_loss": float("nan"),
            "bc_loss": float("nan"),
            "q_mean": float("nan"),
            "q_filter_frac": float("nan"),
        }

        # 1. critic: one-step TD target from the target networks
        if self.uses_critic:
            with torch.no_grad():
                next_q = self.critic_target(batch.next_obs, self.actor_target(batch.next_obs))
                target = batch.rewards + self.gamma * (1.0 - batch.dones) * next_q
            q = self.critic(batch.obs, batch.actions)
            critic_loss = F.mse_loss(q, target)
            self.critic_opt.zero_grad()
            critic_loss.backward()
            self.critic_opt.step()
            out["critic_loss"] = float(critic_loss.detach())
            out["q_mean"] = float(q.detach().mean())

        # 2. actor: DDPG loss + Q-filtered behaviour cloning
        pi, raw = self.actor.outputs(batch.obs)
        actor_loss = torch.zeros((), device=self.device)
        features = None
        use_rl = self.rl_weight > 0 and not pretrain
        use_filter = self.q_filter and not pretrain
        if use_rl or (self.bc_weight > 0 and use_filter):
            with torch.no_grad():  # the actor loss trains the actor only
                features = self.critic.encoder(batch.obs)
        if use_rl and features is not None:
            actor_loss = actor_loss - self.rl_weight * self.critic.q(features, pi).mean()
            actor_loss = actor_loss + self.logit_penalty * (raw**2).mean()
        if self.bc_weight > 0:
            rows = torch.ones_like(batch.expert_valid)
            if not self.bc_on_agent:
                rows[n_demo:] = 0.0
            mask = batch.expert_valid * rows
            if use_filter and features is not None:
                with torch.no_grad():
                    q_expert = self.critic.q(features, batch.expert_actions)
                    q_pi = self.critic.q(features, pi.detach())
                    keep = (q_expert > q_pi).to(pi.dtype)
                out["q_filter_frac"] = float((keep * mask).sum() / mask.sum().clamp(min=1.0))
                mask = mask * keep
            if self.bc_choice:  # cross-entropy on which of the expert's choices is the target
                scores = self.actor.choice_scores(batch.obs, raw)
                assert batch.obs.advice is not None
                target = choice_targets(batch.obs.advice, batch.expert_actions)
                sq = F.cross_entropy(scores, target, reduction="none")
            else:
                sq = ((pi - batch.expert_actions) ** 2).sum(dim=1)
            bc_loss = (sq * mask).sum() / (batch.expert_valid * rows).sum().clamp(min=1.0)
            actor_loss = actor_loss + self.bc_weight * bc_loss
            out["bc_loss"] = float(bc_loss.detach())
        self.actor_opt.zero_grad()
        actor_loss.backward()
        self.actor_opt.step()
        # the critic's gradients from the actor loss are discarded at its next zero_grad
        out["actor_loss"] = float(actor_loss.detach())

        # 3. targets
        self.n_updates += 1
        if self.target_update == "polyak":
            self._polyak()
        elif self.n_updates % self.target_period == 0:
            self.actor_target.load_state_dict(self.actor.state_dict())
            self.critic_target.load_state_dict(self.critic.state_dict())
        return out

    @torch.no_grad()
    def _polyak(self) -> None:
        for net, tgt in ((self.actor, self.actor_target), (self.critic, self.critic_target)):
            for p, tp in zip(net.parameters(), tgt.parameters(), strict=True):
                tp.mul_(1.0 - self.tau).add_(p, alpha=self.tau)

    def state_dict(self) -> dict[str, Any]:
        """Everything needed to continue training."""
        return {
            "actor": self.actor.state_dict(),
            "critic": self.critic.state_dict(),
            "actor_target": self.actor_target.state_dict(),
            "critic_target": self.critic_target.state_dict(),
            "actor_opt": self.actor_opt.state_dict(),
            "critic_opt": self.critic_opt.state_dict(),
            "n_updates": self.n_updates,
        }

    def load_state_dict(self, state: dict[str, Any]) -> None:
        """Restore :meth:`state_dict`."""
        self.actor.load_state_dict(state["actor"])
        self.critic.load_state_dict(state["critic"])
        self.actor_target.load_state_dict(state["actor_target"])
        self.critic_target.load_state_dict(state["critic_target"])
        self.actor_opt.load_state_dict(state["actor_opt"])
        self.critic_opt.load_state_dict(state["critic_opt"])
        self.n_updates = int(state["n_updates"])
