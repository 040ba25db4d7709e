"""Training loop: loss goes down, determinism, checkpoints, resume."""

from __future__ import annotations

import csv
import os
from pathlib import Path

import numpy as np
import pytest
import torch

from slicerecon.errors import FormatError, OptionError
from slicerecon.policy.buffers import ReplayBuffer
from slicerecon.policy.checkpoint import load_checkpoint
from slicerecon.policy.env import CutEnv, ShapePool
from slicerecon.policy.train import CONFIG_NAMES, TrainConfig, config_path, load_config, train
from slicerecon.policy.weights import load_actor

TINY = dict(
    shapes=("box", "two_spheres", "torus"),
    train_shapes=2,
    eval_shapes=1,
    grid=24,
    resolution=32,
    max_corners=8,
    max_steps=4,
    n_envs=4,
    channels=4,
    hidden=32,
    batch_size=32,
    buffer_size=2000,
    log_every=10,
    eval_every=50,
    checkpoint_every=50,
)


def _il(**changes: object) -> TrainConfig:
    base = dict(
        TINY,
        name="il",
        demo_episodes=12,
        explore=False,
        rl_weight=0.0,
        bc_weight=1.0,
        q_filter=False,
        bc_on_agent=False,
        actor_lr=3e-3,
        total_updates=100,
    )
    base.update(changes)
    return TrainConfig(**base)  # type: ignore[arg-type]


def _il_rl(**changes: object) -> TrainConfig:
    base = dict(
        TINY,
        name="il_rl",
        demo_episodes=6,
        pretrain_updates=4,
        total_updates=10,
        explore=True,
        rl_weight=1.0,
        bc_weight=1.0,
        q_filter=True,
        bc_on_agent=True,
    )
    base.update(changes)
    return TrainConfig(**base)  # type: ignore[arg-type]


def _tiny_env(
    families: list[str], seeds: list[int], *, n_envs: int = 1, **options: object
) -> CutEnv:
    """An env with TINY's grid and network sizes on the given shapes."""
    return CutEnv(
        ShapePool.build(families, seeds, grid=TINY["grid"]),
        n_envs=n_envs,
        max_corners=TINY["max_corners"],
        resolution=TINY["resolution"],
        max_steps=TINY["max_steps"],
        **options,  # type: ignore[arg-type]
    )


def _rows(path: Path) -> list[dict[str, str]]:
    with open(path, newline="") as fh:
        return list(csv.DictReader(fh))


def test_behaviour_cloning_loss_goes_down(tmp_path: Path) -> None:
    """~100 updates of imitation on tiny shapes: the BC loss drops clearly."""
    losses: list[float] = []
    result = train(_il(), out=tmp_path, progress=lambda u, n, m: losses.append(m["bc_loss"]))
    assert result.n_updates == 100 and len(losses) == 100
    first, last = np.mean(losses[:20]), np.mean(losses[-20:])
    assert last < 0.7 * first, (first, last)
    rows = _rows(result.log_path)
    assert [int(r["update"]) for r in rows] == list(range(10, 101, 10))
    assert rows[-1]["eval_iou"] and 0.0 < float(rows[-1]["eval_iou"]) <= 1.0
    assert result.actor_path.is_file() and (tmp_path / "checkpoint.pt").is_file()


def test_same_seed_same_parameters(tmp_path: Path) -> None:
    a = train(_il_rl(), out=tmp_path / "a").agent
    b = train(_il_rl(), out=tmp_path / "b").agent
    c = train(_il_rl(seed=1), out=tmp_path / "c").agent
    for net in ("actor", "critic"):
        sa, sb, sc = (getattr(x, net).state_dict() for x in (a, b, c))
        for key in sa:
            torch.testing.assert_close(sa[key], sb[key], rtol=0, atol=0)
        assert any(not torch.equal(sa[k], sc[k]) for k in sa)


def test_saved_actor_acts_identically(tmp_path: Path) -> None:
    result = train(_il_rl(), out=tmp_path)
    actor, meta = load_actor(result.actor_path)
    assert meta["grid"] == 24 and meta["net"]["max_corners"] == 8
    pool = ShapePool.build(["chair", "torus"], [5], grid=24)
    env = CutEnv(pool, n_envs=2, resolution=32, max_corners=8, augment=False)
    obs = env.reset(seed=0)
    with torch.no_grad():
        torch.testing.assert_close(actor(obs), result.agent.act(obs), rtol=0, atol=0)
    # the safetensors file holds plain tensors: also loadable without the library
    from safetensors.torch import load_file

    tensors = load_file(str(result.actor_path))
    assert set(tensors) == set(actor.state_dict())


def test_resume_continues_from_checkpoint(tmp_path: Path) -> None:
    cfg = _il_rl(total_updates=8, checkpoint_every=4, log_every=4, eval_every=4)
    first = train(cfg, out=tmp_path)
    assert first.n_updates == 8
    ckpt = torch.load(tmp_path / "checkpoint.pt", weights_only=False)
    assert ckpt["agent"]["n_updates"] == 8
    more = train(cfg.replace(total_updates=12), out=tmp_path, resume=True)
    assert more.n_updates == 12
    rows = _rows(more.log_path)
    assert [int(r["update"]) for r in rows] == [4, 8, 12]
    # the replay buffers came back: more agent transitions than one run of 4 updates makes
    replay = ReplayBuffer(cfg.buffer_size, resolution=32, max_corners=8)
    replay.load_state_dict(torch.load(tmp_path / "checkpoint.pt", weights_only=False)["replay"])
    assert len(replay) == 8 * cfg.n_envs
    with pytest.raises(OptionError):
        train(cfg.replace(lam=0.5), out=tmp_path, resume=True)


def test_shipped_configs_load_and_bad_files_fail(tmp_path: Path) -> None:
    for name in ("ddpg", "il", "il_rl"):
        cfg = load_config(name)
        assert cfg.name == name and config_path(name).is_file()
    assert load_config("ddpg").bc_weight == 0 and load_config("ddpg").demo_episodes == 0
    assert load_config("il").rl_weight == 0 and not load_config("il").explore
    il_rl = load_config("il_rl", seed=3)
    assert il_rl.q_filter and il_rl.pretrain_updates > 0 and il_rl.seed == 3
    bad = tmp_path / "bad.toml"
    bad.write_text("learning_rate = 3\n")
    with pytest.raises(FormatError, match="learning_rate"):
        load_config(bad)
    bad.write_text("grid = [\n")
    with pytest.raises(FormatError):
        load_config(bad)
    with pytest.raises(OptionError):
        TrainConfig(noise="pink")
    with pytest.raises(OptionError):
        TrainConfig(explore=False)  # imitation without demonstrations


def test_shapes_without_expert_cuts_give_a_clear_error(tmp_path: Path) -> None:
    """A box and a sphere have no splitting segment: no demonstrations can be collected."""
    with pytest.raises(OptionError, match="no cut"):
        train(_il(shapes=("box", "sphere"), demo_episodes=4), out=tmp_path)


class _RunsCode:
    """Unpickling this object calls ``os.mkdir(marker)``: a stand-in for any code."""

    def __init__(self, marker: Path) -> None:
        self.marker = str(marker)

    def __reduce__(self) -> tuple[object, tuple[str]]:
        return os.mkdir, (self.marker,)


def test_resume_refuses_a_checkpoint_that_would_run_code(tmp_path: Path) -> None:
    cfg = _il_rl(total_updates=4, checkpoint_every=4, log_every=4, eval_every=4)
    train(cfg, out=tmp_path)
    ckpt_path = tmp_path / "checkpoint.pt"
    good = torch.load(ckpt_path, weights_only=True)
    marker = tmp_path / "code-ran"
    good["rows"].append({"update": _RunsCode(marker)})  # a tampered, otherwise valid file
    torch.save(good, ckpt_path)
    before = ckpt_path.read_bytes()
    with pytest.raises(FormatError, match="checkpoint.pt") as info:
        train(cfg.replace(total_updates=8), out=tmp_path, resume=True)
    assert "loaded safely" in str(info.value) and "mkdir" in str(info.value)
    assert not marker.exists()  # refused before the object was built
    assert ckpt_path.read_bytes() == before  # and nothing was overwritten
    # the payload is live: the unsafe load the trainer used to do would have run it
    torch.load(ckpt_path, weights_only=False)
    assert marker.is_dir()


@pytest.mark.parametrize(
    "content, message",
    [
        (b"", "loaded safely"),
        (b"not a checkpoint at all", "loaded safely"),
        ({"config": {}, "rng": {"numpy": np.zeros(3)}}, "loaded safely"),  # pickled numpy
        ({"config": {}, "agent": {}}, "missing or wrong: demos"),
        ([1, 2, 3], "not a slicerecon training checkpoint"),
    ],
)
def test_unusable_checkpoints_give_one_clear_error(
    tmp_path: Path, content: object, message: str
) -> None:
    path = tmp_path / "checkpoint.pt"
    if isinstance(content, bytes):
        path.write_bytes(content)
    else:
        torch.save(content, path)
    with pytest.raises(FormatError, match=message) as info:
        load_checkpoint(path)
    assert str(path) in str(info.value)
    assert "\n" not in str(info.value)
    with pytest.raises(FormatError, match=message):
        train(_il_rl(), out=tmp_path, resume=True)


def test_checkpoint_of_other_networks_is_refused_clearly(tmp_path: Path) -> None:
    cfg = _il_rl(total_updates=4, checkpoint_every=4, log_every=4, eval_every=4)
    train(cfg, out=tmp_path)
    ckpt = torch.load(tmp_path / "checkpoint.pt", weights_only=True)
    ckpt["agent"]["actor"] = {"weight": torch.zeros(3)}
    torch.save(ckpt, tmp_path / "checkpoint.pt")
    with pytest.raises(FormatError, match="does not fit"):
        train(cfg, out=tmp_path, resume=True)


def test_gain_configs_train_only_on_development_real_shapes() -> None:
    """The real shapes a shipped or benchmark config trains on are all in the development
    half, and the *_gain configs share one gain setting (ddpg_gain's)."""
    import tomllib

    benchmarks = Path(__file__).resolve().parents[2] / "benchmarks"
    cases = tomllib.loads((benchmarks / "real_split.toml").read_text())["cases"]
    dev = {name for name, case in cases.items() if case["half"] == "dev"}
    files = sorted((benchmarks / "configs").glob("*.toml"))
    configs = [load_config(name) for name in CONFIG_NAMES] + [load_config(f) for f in files]
    assert {"il_gain", "il_rl_gain", "il_rl_choice", "il_rl_gpu"} <= {c.name for c in configs}
    setting = ("reward", "real_shapes", "real_variants", "max_stretch", "planes_min", "planes_max")
    gain = load_config("ddpg_gain")
    assert gain.reward == "gain" and len(gain.real_shapes) == 19
    assert set(gain.real_shapes) <= dev, set(gain.real_shapes) - dev
    for cfg in configs:
        assert set(cfg.real_shapes) <= dev, (cfg.name, set(cfg.real_shapes) - dev)
        if cfg.name.endswith(("_gain", "_choice", "_gpu")):
            assert [getattr(cfg, k) for k in setting] == [getattr(gain, k) for k in setting]
            assert cfg.keep_best and cfg.expert_stops == (cfg.demo_episodes > 0), cfg.name
    with pytest.raises(OptionError):
        TrainConfig(reward="area")


def test_gain_reward_with_demonstrated_stops_trains_and_stops(tmp_path: Path) -> None:
    """expert_stops: the no-cut states are demonstrated as the stop (zeros) and cloned."""
    cfg = _il(reward="gain", expert_stops=True, total_updates=150, actor_lr=3e-3)
    result = train(cfg, out=tmp_path / "run", device="cpu")
    rows = _rows(result.log_path)
    assert float(rows[-1]["bc_loss"]) < float(rows[0]["bc_loss"])
    # a box has corners but no splitting segment: the expert stops at once, so does its clone
    env = _tiny_env(["box"], [0], reward="gain", augment=False)
    obs = env.reset(seed=0, shapes=[0])
    assert env.corner_valid.sum() >= 4
    with torch.no_grad():
        action = result.agent.actor.eval()(obs)
    out = env.step(action)
    assert float(action.max()) < 0.05
    assert env.last_step is not None and bool(env.last_step.cuts.degenerate[0])
    assert bool(out.noop[0]) and out.reward[0].item() == 0.0


def test_an_untrained_chooser_plans_like_the_heuristic(tmp_path: Path) -> None:
    """candidates: before any update the actor is the expert, through a weights file too."""
    from slicerecon.partition.planner import plan_partition
    from slicerecon.policy.networks import Actor
    from slicerecon.policy.weights import save_actor
    from slicerecon.shapes import make_shape

    cfg = _il_rl(candidates=3, reward="gain", expert_stops=True)
    torch.manual_seed(3)
    path = save_actor(Actor(cfg.net), tmp_path / "chooser.safetensors", extra={"max_steps": 4})
    assert load_actor(path)[0].config.candidates == 3
    for family, seed in (("chair", 12345), ("table", 7), ("box", 0)):
        occ = make_shape(family, seed=seed, spacing=2.5).mask
        expert = plan_partition(occ, planner="heuristic", max_parts=5)
        learned = plan_partition(occ, planner="policy", max_parts=5, weights=path)
        assert [p.box for p in learned.parts] == [p.box for p in expert.parts], family
    # the heuristic has no cut on a box: the stop is the only choice, and the actor stops
    assert len(learned.parts) == 1


def test_chooser_trains_keeps_its_candidates_and_resumes(tmp_path: Path) -> None:
    """The expert's cuts travel through both buffers, training, a checkpoint and a weights file."""
    cfg = _il_rl(candidates=3, reward="gain", expert_stops=True, total_updates=12)
    first = train(cfg, out=tmp_path / "run", device="cpu")
    actor, meta = load_actor(first.actor_path)
    assert actor.config.candidates == 3 and meta["config"]["candidates"] == 3
    again = train(cfg.replace(total_updates=16), out=tmp_path / "run", device="cpu", resume=True)
    assert again.n_updates == 16
    env = _tiny_env(["two_spheres"], [0], augment=False)
    with pytest.raises(OptionError, match="candidates=3"):
        actor(env.reset(seed=0))  # an env without the expert's cuts cannot feed this actor
    env.candidates = 3
    obs = env.observation()
    action = actor(obs)
    assert tuple(action.shape) == (1, 5) and obs.advice is not None
    assert tuple(obs.advice.shape) == (1, 3, 6)
    buffer = ReplayBuffer(8, resolution=32, max_corners=8, candidates=3)
    one, five = torch.zeros(1), torch.zeros((1, 5))
    buffer.add(obs, five, one, obs, one, five, one)
    batch = buffer.sample(2, generator=torch.Generator().manual_seed(0))
    assert batch.obs.advice is not None and torch.equal(batch.obs.advice[0], obs.advice[0])
    with pytest.raises(OptionError, match="advice"):
        buffer.add(obs._replace(advice=None), five, one, obs, one, five, one)


def test_a_chooser_acts_within_the_expert_cuts_and_the_stop() -> None:
    """Its action is a convex mix of the valid cuts' actions and zeros; invalid rows get none."""
    from slicerecon.policy.networks import Actor, NetConfig
    from slicerecon.policy.observation import Observation

    torch.manual_seed(0)
    actor = Actor(NetConfig(32, 8, 4, 32, candidates=3))
    torch.nn.init.normal_(actor.head[-1].weight, std=3.0)  # a trained-looking head
    advice = torch.zeros((4, 3, 6))
    advice[:, 0] = torch.tensor([0.2, 0.3, 0.4, 0.5, 0.1, 1.0])
    advice[:2, 1] = torch.tensor([0.6, 0.6, 0.9, 0.9, 0.9, 1.0])
    obs = Observation(
        torch.rand((4, 3, 32, 32)), torch.rand((4, 1)), torch.rand((4, 3, 8, 2)),
        torch.ones((4, 3, 8)), advice,
    )  # fmt: skip
    action = actor(obs)
    lo = torch.zeros(5)
    hi = torch.maximum(advice[:, 0, :5], advice[:, 1, :5])
    assert torch.all(action >= lo - 1e-6) and torch.all(action <= hi + 1e-6)
    # rows 2 and 3 have one valid cut: the action lies on the segment from zeros to it
    ratio = action[2:] / advice[2:, 0, :5]
    assert torch.allclose(ratio, ratio[:, :1].expand_as(ratio), atol=1e-5)


def test_lookahead_demonstrations_are_cloned(tmp_path: Path) -> None:
    """demo_lookahead: R_D holds the lookahead's choices, and imitation of them trains."""
    from slicerecon.policy.demos import collect_lookahead_demos, episode_state

    cfg = _il(reward="gain", candidates=3, demo_lookahead=3, demo_margin=0.0, total_updates=30)
    result = train(cfg, out=tmp_path / "run", device="cpu")
    assert np.isfinite(float(_rows(result.log_path)[-1]["bc_loss"]))
    env = _tiny_env(["box", "two_spheres", "torus"], [0, 1], n_envs=2, reward="gain", candidates=3)
    buffer = ReplayBuffer(500, resolution=32, max_corners=8, candidates=3)
    mean_return = collect_lookahead_demos(env, buffer, 4, 0, candidates=3, margin=0.0)
    assert len(buffer) >= 4 and np.isfinite(mean_return)
    batch = buffer.sample(len(buffer), generator=torch.Generator().manual_seed(0))
    assert torch.equal(batch.actions, batch.expert_actions)  # the cloning target is the choice
    assert batch.obs.advice is not None
    env.reset(seed=0)
    assert episode_state(env, 0).potential() == pytest.approx(env.potential[0], abs=1e-9)
    with pytest.raises(OptionError):
        TrainConfig(demo_lookahead=2, reward_surface="surrogate")


def test_weights_of_unknown_network_sizes_give_one_clear_error(tmp_path: Path) -> None:
    """A weights file from another version (an unknown size field) is a FormatError naming it."""
    import json

    from safetensors import safe_open
    from safetensors.torch import load_file, save_file

    from slicerecon.policy.networks import Actor
    from slicerecon.policy.weights import save_actor

    path = save_actor(Actor(_il().net), tmp_path / "a.safetensors")
    with safe_open(str(path), framework="pt") as fh:
        meta = dict(fh.metadata())
    net = json.loads(meta["net"])
    net["advice"] = True  # a field an older experiment wrote
    meta["net"] = json.dumps(net)
    save_file(load_file(str(path)), str(tmp_path / "b.safetensors"), metadata=meta)
    with pytest.raises(FormatError, match="advice"):
        load_actor(tmp_path / "b.safetensors")


def test_choice_targets_and_the_cross_entropy_cloning_loss(tmp_path: Path) -> None:
    """bc_loss = choice: targets are matched to the nearest valid choice, and cloning learns it."""
    from slicerecon.policy.networks import choice_targets

    advice = torch.zeros((3, 2, 6))
    advice[:, 0] = torch.tensor([0.2, 0.2, 0.8, 0.8, 0.1, 1.0])
    advice[:2, 1] = torch.tensor([0.5, 0.1, 0.5, 0.9, 0.5, 1.0])
    targets = torch.tensor(
        [[0.5, 0.1, 0.5, 0.9, 0.5], [0.0, 0.0, 0.0, 0.0, 0.0], [0.5, 0.1, 0.5, 0.9, 0.5]]
    )
    # the second cut of row 2 is invalid: its nearest valid choice is the first cut
    assert choice_targets(advice, targets).tolist() == [1, 2, 0]
    cfg = _il(candidates=3, bc_loss="choice", demo_lookahead=3, demo_margin=0.0, reward="gain")
    result = train(cfg.replace(total_updates=60), out=tmp_path / "run", device="cpu")
    losses = [float(r["bc_loss"]) for r in _rows(result.log_path)]
    assert all(np.isfinite(losses)) and losses[-1] <= losses[0]
    with pytest.raises(OptionError):
        TrainConfig(bc_loss="choice")  # needs a chooser
    with pytest.raises(OptionError):
        TrainConfig(bc_loss="l1")
