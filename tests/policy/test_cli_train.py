"""``slicerecon train`` on a tiny config file."""

from __future__ import annotations

import json
import os
from pathlib import Path

import pytest

from slicerecon.cli import main

TINY_TOML = """
name = "tiny"
shapes = ["two_spheres", "chair"]
train_shapes = 2
eval_shapes = 1
grid = 20
resolution = 16
max_corners = 6
max_steps = 3
n_envs = 2
channels = 4
hidden = 16
batch_size = 8
buffer_size = 500
demo_episodes = 4
explore = false
rl_weight = 0.0
bc_weight = 1.0
q_filter = false
bc_on_agent = false
total_updates = 6
log_every = 3
eval_every = 3
checkpoint_every = 3
"""


def test_train_command_writes_outputs_and_resumes(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    cfg = tmp_path / "tiny.toml"
    cfg.write_text(TINY_TOML)
    out = tmp_path / "run"
    assert main(["train", "--config", str(cfg), "--out", str(out), "--threads", "1"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["updates"] == 6 and 0 < summary["eval_iou"] <= 1
    assert {p.name for p in out.iterdir()} >= {
        "log.csv",
        "checkpoint.pt",
        "actor.safetensors",
        "config.json",
    }
    args = ["train", "--config", str(cfg), "--out", str(out), "--resume", "--steps", "9"]
    assert main(args) == 0
    assert json.loads(capsys.readouterr().out)["updates"] == 9


@pytest.mark.parametrize(
    "args, message",
    [
        (["--device", "gpu"], "--device must be cpu or cuda"),
        (["--config", "missing.toml"], "config file not found"),
        (["--config", "il_rl", "--threads", "0"], "--threads must be >= 1"),
    ],
)
def test_train_command_bad_options(
    args: list[str], message: str, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["train", *args]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and message in err[0]


class _RunsCode:
    def __init__(self, marker: Path) -> None:
        self.marker = str(marker)

    def __reduce__(self) -> tuple[object, tuple[str]]:
        return os.mkdir, (self.marker,)


def test_train_resume_refuses_an_unsafe_checkpoint_with_one_error_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    import torch

    cfg = tmp_path / "tiny.toml"
    cfg.write_text(TINY_TOML)
    out = tmp_path / "run"
    out.mkdir()
    marker = tmp_path / "code-ran"
    torch.save({"config": {"name": "tiny"}, "agent": _RunsCode(marker)}, out / "checkpoint.pt")
    args = ["train", "--config", str(cfg), "--out", str(out), "--resume", "--threads", "1"]
    assert main(args) == 2
    captured = capsys.readouterr()
    errors = [line for line in captured.err.splitlines() if line.startswith("error:")]
    assert len(errors) == 1 and "Traceback" not in captured.err, captured.err
    assert str(out / "checkpoint.pt") in errors[0] and "loaded safely" in errors[0]
    assert not marker.exists()


def test_train_help_names_every_shipped_config(capsys: pytest.CaptureFixture[str]) -> None:
    from slicerecon.policy.config import CONFIG_NAMES, config_path

    assert main(["train", "--help"]) in (0, None)
    text = " ".join(capsys.readouterr().out.split())
    for name in CONFIG_NAMES:
        assert config_path(name).is_file()
        assert f"{name}," in text or f"{name}." in text, name


def test_a_written_pool_trains_without_building_and_is_checked(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """--write-pool writes the config's training shapes; --pool trains on them; a pool of
    another config, or a damaged file, is refused with one error line."""
    from slicerecon.partition.episodes import ShapePool
    from slicerecon.policy.config import load_config
    from slicerecon.policy.train import training_pool

    cfg = tmp_path / "tiny.toml"
    cfg.write_text(TINY_TOML)
    pool = tmp_path / "pool.npz"
    assert main(["train", "--config", str(cfg), "--write-pool", str(pool)]) == 0
    assert json.loads(capsys.readouterr().out) == {"pool": str(pool), "grids": 4, "grid": 20}
    built = training_pool(load_config(str(cfg)))
    loaded = ShapePool.load(pool)
    assert loaded.names == built.names and loaded.seeds == built.seeds
    assert (loaded.occupancies == built.occupancies).all()
    out = tmp_path / "run"
    args = ["train", "--config", str(cfg), "--out", str(out), "--pool", str(pool)]
    assert main([*args, "--threads", "1"]) == 0
    assert json.loads(capsys.readouterr().out)["updates"] == 6

    other = tmp_path / "other.toml"
    other.write_text(TINY_TOML.replace("train_shapes = 2", "train_shapes = 3"))
    assert main(["train", "--config", str(other), "--out", str(out), "--pool", str(pool)]) == 2
    assert "is not the shape pool of config" in capsys.readouterr().err
    bad = tmp_path / "bad.npz"
    bad.write_bytes(b"not a pool")
    assert main(["train", "--config", str(cfg), "--out", str(out), "--pool", str(bad)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "not a shape pool" in err[0]
