"""Settings of a training run of the learned planner: :class:`TrainConfig` and the shipped configs.

A config is a TOML file whose top-level keys are :class:`TrainConfig` fields
(:func:`load_config`); the shipped ones live in ``slicerecon/policy/configs/``
(:data:`CONFIG_NAMES`, :func:`config_path`). A file may start from another
config with ``extends = "NAME"`` (a shipped config) or ``extends = "FILE.toml"``
(relative to the file) and list only what differs, so that a block of settings
several configs share is written once. :func:`slicerecon.policy.train.train`
runs one.
"""

from __future__ import annotations

import dataclasses
import os
import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ..errors import FormatError, InputError, OptionError
from ..partition.state import REWARD_KINDS
from .ddpg import TARGET_UPDATES
from .networks import NetConfig
from .reward import REWARD_SURFACES

__all__ = [
    "TrainConfig",
    "EVAL_SEED_OFFSET",
    "CONFIG_NAMES",
    "NOISES",
    "config_path",
    "load_config",
]

EVAL_SEED_OFFSET = 10_000
"""Evaluation shapes use seeds from here on; training seeds stay below it."""

CONFIG_NAMES = ("ddpg", "il", "il_rl", "ddpg_gain")
"""The shipped configs in ``slicerecon/policy/configs/``: the paper's three
(``ddpg``, ``il``, ``il_rl``) and the best current one (``ddpg_gain``,
``docs/policy.md``). Other experiments' configs are in ``benchmarks/configs/``
and load by path."""

NOISES = ("gaussian", "ou")


@dataclass(frozen=True)
class TrainConfig:
    """Every setting of a training run (fields of a TOML file, all optional)."""

    name: str = "il_rl"
    """Run name, recorded in the outputs."""
    seed: int = 0
    """Seed of torch and numpy (network init, episode draws, noise, minibatches)."""
    shapes: tuple[str, ...] = ()
    """Shape families to train on; empty: every family ``slicerecon.shapes`` registers."""
    real_shapes: tuple[str, ...] = ()
    """Real shapes (:mod:`slicerecon.realshapes` names) added to the training pool
    (:func:`~slicerecon.partition.episodes.real_occupancy`); only ever the
    development half of ``benchmarks/real_split.toml`` (a test checks the
    shipped and the benchmark configs). Missing source packages are skipped
    with a warning."""
    real_variants: int = 1
    """Copies of each real shape in the pool: as it is, then stretched per axis."""
    max_stretch: float = 1.5
    """Largest per-axis stretch of a real shape's copies (anisotropic rescaling)."""
    train_shapes: int = 16
    """Seeds per family for training (seeds ``0 .. train_shapes - 1``)."""
    eval_shapes: int = 3
    """Seeds per family for evaluation (seeds ``EVAL_SEED_OFFSET + i``)."""
    grid: int = 32
    """Side of the cubic voxel grid every shape is scaled into."""
    resolution: int = 32
    """Side ``R`` of the observed silhouettes."""
    max_corners: int = 16
    """Corners per view ``K`` in the state."""
    max_steps: int = 7
    """Cuts per episode (``max_parts - 1`` of the planner)."""
    min_remaining: float = 0.02
    """An episode ends when less than this fraction of the shape remains."""
    lam: float = 1.0
    """Weight ``lambda`` of the reconstruction term of the paper's reward."""
    reward: str = "paper"
    """What a step's reward measures: ``paper`` (``IoU(W_i, O) + lam IoU(S_i, W_i)``)
    or ``gain`` (the change of the whole reconstruction's IoU with ``O``,
    :data:`~slicerecon.partition.state.REWARD_KINDS`)."""
    planes_min: int = 8
    """Fewest section planes (along z) the reward reconstructs a part from."""
    planes_max: int = 16
    """Most section planes (drawn per episode)."""
    reward_surface: str = "exact"
    """The reward's reconstruction of a part: ``exact`` (the part surface
    inference makes; numpy on the CPU, a few ms per part) or ``surrogate`` (its
    batched torch approximation, for a GPU); ``docs/policy.md`` gives their
    agreement and speed."""
    augment: bool = True
    """Randomly permute and flip the axes of each training shape."""
    n_envs: int = 8
    """Episodes stepped together."""
    channels: int = 16
    """Channels of the first convolution."""
    hidden: int = 128
    """Width of the MLP layers."""
    candidates: int = 0
    """``C > 0``: the networks read the heuristic expert's first ``C`` cuts at
    each state and the actor chooses among them and the stop
    (:class:`~slicerecon.policy.networks.NetConfig`); an untrained actor is
    the expert, its stop included. 0: the paper's free actor."""
    demo_episodes: int = 0
    """Heuristic episodes put in ``R_D`` before training; 0: no demonstrations."""
    pretrain_updates: int = 0
    """Phase I: updates on the demonstrations alone."""
    total_updates: int = 2000
    """Updates in all (Phase I included)."""
    explore: bool = True
    """Phase II: collect agent experience in ``R_A`` (False: learn from ``R_D`` only)."""
    updates_per_step: int = 1
    """Updates per batched environment step in Phase II."""
    learning_starts: int = 256
    """Agent transitions (random actions) collected before the first update without demos."""
    batch_size: int = 64
    """Minibatch size drawn from each buffer."""
    buffer_size: int = 20_000
    """Capacity of each replay buffer, transitions."""
    gamma: float = 0.95
    """Discount factor."""
    actor_lr: float = 1e-4
    """Adam learning rate of the actor."""
    critic_lr: float = 1e-3
    """Adam learning rate of the critic."""
    rl_weight: float = 1.0
    """Weight of the DDPG actor loss; 0: no reinforcement learning."""
    bc_weight: float = 0.0
    """Weight of the behaviour-cloning loss; 0: no cloning."""
    q_filter: bool = True
    """Apply the Q-filter to the cloning loss."""
    bc_on_agent: bool = True
    """Clone the expert on agent samples too (needs the expert at every agent state)."""
    expert_stops: bool = False
    """Where the heuristic has no useful cut left, its action is the stop (a
    degenerate no-op, all zeros) and is demonstrated and cloned as such;
    False: such states have no expert action (the actor never learns to stop)."""
    demo_lookahead: int = 0
    """0: the demonstrations are the heuristic expert's. ``n > 0``: they are
    its one-step lookahead (:func:`~slicerecon.partition.lookahead.lookahead_cut`
    over its first ``n`` cuts and the stop, each finished by the expert and
    scored on the known shape), a teacher at least as good on the states it
    is asked about; the cloning target of the demonstrations is its action."""
    bc_loss: str = "mse"
    """The cloning loss: ``mse`` (the paper's squared distance of the actions)
    or ``choice`` (for a chooser, ``candidates > 0``: the cross-entropy of
    its scores with the index of the target among its choices)."""
    demo_margin: float = 0.002
    """The lookahead leaves the expert's choice only for an IoU higher by more than this."""
    noise: str = "gaussian"
    """Exploration noise: ``gaussian`` or ``ou`` (Ornstein-Uhlenbeck)."""
    noise_sigma: float = 0.1
    """Standard deviation of the exploration noise (actions live in [0, 1])."""
    explore_stops: float = 0.0
    """Share of exploring steps whose action is the stop (all zeros) instead of
    the noisy actor's, so that the critic learns what stopping is worth."""
    target_update: str = "hard"
    """``hard``: copy the networks every ``target_period`` updates; ``polyak``: rate ``tau``."""
    target_period: int = 100
    """Updates between hard target copies."""
    tau: float = 0.005
    """Polyak rate."""
    logit_penalty: float = 1e-3
    """Weight of the penalty on the actor's pre-sigmoid outputs (with the DDPG loss)."""
    eval_every: int = 250
    """Updates between evaluations on the held-out shapes."""
    keep_best: bool = False
    """Also write ``actor_best.safetensors``: the actor of the evaluation with the
    highest IoU (early stopping on the training's own evaluation shapes, seeds
    ``EVAL_SEED_OFFSET + i``, never on a benchmark's held-out shapes)."""
    log_every: int = 50
    """Updates between CSV log rows."""
    checkpoint_every: int = 500
    """Updates between checkpoints (one at the end always)."""

    def __post_init__(self) -> None:
        object.__setattr__(self, "shapes", tuple(str(s) for s in self.shapes))
        object.__setattr__(self, "real_shapes", tuple(str(s) for s in self.real_shapes))
        positive = (
            "train_shapes",
            "eval_shapes",
            "grid",
            "resolution",
            "max_corners",
            "max_steps",
            "n_envs",
            "channels",
            "hidden",
            "total_updates",
            "updates_per_step",
            "batch_size",
            "buffer_size",
            "target_period",
            "eval_every",
            "log_every",
            "checkpoint_every",
            "planes_min",
            "real_variants",
        )
        for name in positive:
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise OptionError(f"{name} must be a positive integer (got {value!r})")
        for name in (
            "demo_episodes",
            "pretrain_updates",
            "learning_starts",
            "seed",
            "candidates",
            "demo_lookahead",
        ):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < 0:
                raise OptionError(f"{name} must be an integer >= 0 (got {value!r})")
        if self.planes_max < self.planes_min:
            raise OptionError("planes_max must be >= planes_min")
        if self.grid < 16 or self.resolution < 16:
            raise OptionError("grid and resolution must be >= 16")
        if self.train_shapes > EVAL_SEED_OFFSET:
            raise OptionError(f"train_shapes must be <= {EVAL_SEED_OFFSET}")
        if self.reward_surface not in REWARD_SURFACES:
            raise OptionError(
                f"reward_surface must be one of {', '.join(REWARD_SURFACES)} "
                f"(got {self.reward_surface!r})"
            )
        if self.reward not in REWARD_KINDS:
            raise OptionError(
                f"reward must be one of {', '.join(REWARD_KINDS)} (got {self.reward!r})"
            )
        if not self.max_stretch >= 1.0:
            raise OptionError(f"max_stretch must be >= 1 (got {self.max_stretch!r})")
        if self.noise not in NOISES:
            raise OptionError(f"noise must be one of {', '.join(NOISES)} (got {self.noise!r})")
        if self.target_update not in TARGET_UPDATES:
            raise OptionError(
                f"target_update must be one of {', '.join(TARGET_UPDATES)} "
                f"(got {self.target_update!r})"
            )
        if self.pretrain_updates > 0 and self.demo_episodes == 0:
            raise OptionError("pretrain_updates needs demonstrations (demo_episodes > 0)")
        if not self.explore and self.demo_episodes == 0:
            raise OptionError("explore = false needs demonstrations (demo_episodes > 0)")
        if self.bc_weight > 0 and self.demo_episodes == 0 and not self.bc_on_agent:
            raise OptionError("bc_weight > 0 needs demonstrations or bc_on_agent = true")
        if self.rl_weight < 0 or self.bc_weight < 0 or self.rl_weight + self.bc_weight == 0:
            raise OptionError("rl_weight and bc_weight must be >= 0 and not both 0")
        if not 0 <= self.min_remaining < 1 or self.lam < 0 or not 0 <= self.gamma <= 1:
            raise OptionError("need 0 <= min_remaining < 1, lam >= 0 and 0 <= gamma <= 1")
        if not self.demo_margin >= 0:
            raise OptionError(f"demo_margin must be >= 0 (got {self.demo_margin!r})")
        if self.demo_lookahead and self.reward_surface != "exact":
            raise OptionError("demo_lookahead scores choices with the exact reward surface")
        if self.bc_loss not in ("mse", "choice"):
            raise OptionError(f"bc_loss must be mse or choice (got {self.bc_loss!r})")
        if self.bc_loss == "choice" and not self.candidates:
            raise OptionError("bc_loss = choice needs a chooser (candidates > 0)")
        if not 0.0 <= self.explore_stops <= 1.0:
            raise OptionError(f"explore_stops must be in [0, 1] (got {self.explore_stops!r})")
        if min(self.noise_sigma, self.logit_penalty) < 0 or min(self.actor_lr, self.critic_lr) <= 0:
            raise OptionError("noise_sigma and logit_penalty must be >= 0, learning rates > 0")

    @property
    def net(self) -> NetConfig:
        """Network sizes."""
        return NetConfig(
            self.resolution, self.max_corners, self.channels, self.hidden, self.candidates
        )

    def replace(self, **changes: Any) -> TrainConfig:
        """A copy with some fields changed."""
        return dataclasses.replace(self, **changes)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dict of every field."""
        d = dataclasses.asdict(self)
        d["shapes"] = list(self.shapes)
        d["real_shapes"] = list(self.real_shapes)
        return d


def config_path(name: str) -> Path:
    """Path of a shipped config (a name in :data:`CONFIG_NAMES`)."""
    if name not in CONFIG_NAMES:
        raise OptionError(f"no shipped config {name!r}; choose one of {', '.join(CONFIG_NAMES)}")
    return Path(__file__).with_name("configs") / f"{name}.toml"


def load_config(source: str | os.PathLike[str], **overrides: Any) -> TrainConfig:
    """Read a :class:`TrainConfig` from a TOML file or a shipped config name.

    Parameters
    ----------
    source : str or path-like
        A name in :data:`CONFIG_NAMES` or a path to a ``.toml`` file whose top-level
        keys are :class:`TrainConfig` fields, and optionally ``extends``: a name in
        :data:`CONFIG_NAMES` or a path relative to the file, the config whose
        settings the file's own keys replace (it may extend another in turn).
    **overrides
        Fields to replace (``None`` values are ignored).

    Raises
    ------
    InputError
        If the file is missing.
    FormatError
        If it, or a config it extends, is not TOML or holds an unknown key, or if
        ``extends`` names neither a shipped config nor a file, or makes a cycle.
    """
    text_source = str(source)
    path = config_path(text_source) if text_source in CONFIG_NAMES else Path(text_source)
    if not path.is_file():
        raise InputError(
            f"config file not found: {path} (give a .toml file or one of {', '.join(CONFIG_NAMES)})"
        )
    data = _settings(path, ())
    data.update({k: v for k, v in overrides.items() if v is not None})
    for key in ("shapes", "real_shapes"):
        if key in data:
            data[key] = tuple(data[key])
    try:
        return TrainConfig(**data)
    except TypeError as exc:
        raise FormatError(f"{path}: {exc}") from exc


def _settings(path: Path, chain: tuple[Path, ...]) -> dict[str, Any]:
    """The settings of one config file over those of the config it ``extends``.

    ``chain`` holds the files that extend this one (to refuse a cycle).
    """
    try:
        data = tomllib.loads(path.read_text())
    except tomllib.TOMLDecodeError as exc:
        raise FormatError(f"{path} is not valid TOML: {exc}") from exc
    parent = data.pop("extends", None)
    known = {f.name for f in dataclasses.fields(TrainConfig)}
    unknown = sorted(set(data) - known)
    if unknown:
        raise FormatError(
            f"{path}: unknown setting(s) {', '.join(unknown)}; see TrainConfig for the fields"
        )
    if parent is None:
        return data
    if not isinstance(parent, str):
        raise FormatError(f"{path}: extends must be a config name or a .toml path (got {parent!r})")
    parent_path = config_path(parent) if parent in CONFIG_NAMES else path.parent / parent
    if not parent_path.is_file():
        raise FormatError(
            f"{path}: extends = {parent!r} is neither a shipped config "
            f"({', '.join(CONFIG_NAMES)}) nor a file ({parent_path})"
        )
    chain = (*chain, path.resolve())
    if parent_path.resolve() in chain:
        files = " -> ".join(p.name for p in (*chain, parent_path))
        raise FormatError(f"{path}: extends makes a cycle ({files})")
    return {**_settings(parent_path, chain), **data}
