"""The shipped actors are reproducible: the manifest names a shipped config and the command."""

from __future__ import annotations

import hashlib
import json
import re
import shlex

import pytest

from slicerecon.policy.config import CONFIG_NAMES, config_path, load_config
from slicerecon.policy.weights import SHIPPED, load_actor, shipped_weights

MANIFEST = shipped_weights("il_rl").with_name("manifest.json")


@pytest.fixture(scope="module")
def manifest() -> dict:
    return json.loads(MANIFEST.read_text())


def test_the_manifest_records_every_shipped_actor_and_nothing_else(manifest: dict) -> None:
    assert sorted(manifest["actors"]) == sorted(SHIPPED)
    listed = {entry["file"] for entry in manifest["actors"].values()}
    listed |= {entry["log"] for entry in manifest["actors"].values()}
    present = {p.name for p in MANIFEST.parent.iterdir()} - {"manifest.json", "README.md"}
    assert present == listed


@pytest.mark.parametrize("name", SHIPPED)
def test_the_manifests_command_trains_a_shipped_config(manifest: dict, name: str) -> None:
    """The command is `slicerecon train` on a shipped config, at a recorded commit; the file
    it made exists, is the one hashed, loads, and was trained with that config as it loads
    now (so a config edited after training fails here until the weights are retrained)."""
    entry = manifest["actors"][name]
    argv = shlex.split(entry["command"])
    assert argv[:2] == ["slicerecon", "train"], entry["command"]
    config = argv[argv.index("--config") + 1]
    assert config in CONFIG_NAMES and config == entry["config_name"] == name
    assert entry["config_file"] == f"slicerecon/policy/configs/{config}.toml"
    assert config_path(config).is_file()
    assert re.fullmatch(r"[0-9a-f]{40}", entry["commit"]), entry["commit"]
    assert entry["threads"] == int(argv[argv.index("--threads") + 1])
    path = MANIFEST.with_name(entry["file"])
    assert path == shipped_weights(name) and path.is_file()
    data = path.read_bytes()
    assert hashlib.sha256(data).hexdigest() == entry["sha256"] and len(data) == entry["bytes"]
    actor, meta = load_actor(path)
    assert sum(p.numel() for p in actor.parameters()) > 1000
    assert meta["config"] == load_config(config).to_dict() == entry["config"]
    assert meta["n_updates"] == entry["updates"] == load_config(config).total_updates
    assert meta["heuristic_eval_iou"] == pytest.approx(entry["heuristic_eval_iou"])
    assert MANIFEST.with_name(entry["log"]).is_file()
