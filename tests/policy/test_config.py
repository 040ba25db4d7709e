"""Reading training configs: ``extends`` writes a shared block of settings once."""

from __future__ import annotations

from pathlib import Path

import pytest

from slicerecon.cli import main
from slicerecon.errors import FormatError
from slicerecon.policy.config import CONFIG_NAMES, config_path, load_config

BENCHMARK_CONFIGS = Path(__file__).resolve().parents[2] / "benchmarks" / "configs"


def test_extends_takes_the_parents_settings_under_the_files_own(tmp_path: Path) -> None:
    """A child is its parent with its own keys replaced, through a chain of files."""
    (tmp_path / "base.toml").write_text('extends = "il_rl"\nname = "base"\ntotal_updates = 40\n')
    sub = tmp_path / "sub"
    sub.mkdir()
    (sub / "child.toml").write_text(
        'extends = "../base.toml"\nname = "child"\nshapes = ["torus"]\ngamma = 0.9\n'
    )
    child = load_config(sub / "child.toml", seed=5)
    expected = load_config("il_rl").replace(
        name="child", total_updates=40, shapes=("torus",), gamma=0.9, seed=5
    )
    assert child == expected
    assert load_config(tmp_path / "base.toml") == load_config("il_rl").replace(
        name="base", total_updates=40
    )


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ('extends = "nowhere"\n', r"extends = 'nowhere' is neither a shipped config"),
        ("extends = 3\n", "extends must be a config name or a .toml path"),
        ('extends = "loop.toml"\n', r"extends makes a cycle \(loop.toml -> loop.toml\)"),
        ('extends = "parent.toml"\n', "parent.toml: unknown setting"),
    ],
)
def test_a_bad_extends_is_one_clear_error(tmp_path: Path, text: str, message: str) -> None:
    (tmp_path / "parent.toml").write_text("learning_rate = 3\n")
    path = tmp_path / "loop.toml"
    path.write_text(text)
    with pytest.raises(FormatError, match=message):
        load_config(path)


def test_a_missing_parent_stops_the_train_command_with_one_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = tmp_path / "x.toml"
    path.write_text('extends = "il_rl_tuned"\n')
    assert main(["train", "--config", str(path), "--out", str(tmp_path / "run")]) == 2
    err = capsys.readouterr().err
    errors = [line for line in err.splitlines() if line.startswith("error:")]
    assert len(errors) == 1 and "Traceback" not in err, err
    assert "extends = 'il_rl_tuned'" in errors[0] and "ddpg, il, il_rl" in errors[0]
    assert not (tmp_path / "run").exists()


def test_the_package_ships_the_papers_configs_and_the_best_current_one() -> None:
    """configs/ holds exactly CONFIG_NAMES; each names itself; the experiments' configs in
    benchmarks/configs/ load by path and are named after their files."""
    assert CONFIG_NAMES == ("ddpg", "il", "il_rl", "ddpg_gain")
    assert sorted(p.stem for p in config_path("il").parent.glob("*")) == sorted(CONFIG_NAMES)
    for name in CONFIG_NAMES:
        assert load_config(name).name == name
    files = sorted(BENCHMARK_CONFIGS.glob("*.toml"))
    assert [f.stem for f in files] == ["il_gain", "il_rl_choice", "il_rl_gain", "il_rl_gpu"]
    for path in files:
        assert load_config(path).name == path.stem
