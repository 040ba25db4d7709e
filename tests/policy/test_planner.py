"""The learned planner with the shipped weights."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest
from safetensors import safe_open

from slicerecon.errors import OptionError
from slicerecon.partition.planner import PLANNERS, plan_partition
from slicerecon.policy.weights import SHIPPED, load_actor, shipped_weights
from slicerecon.shapes import make_shape


@pytest.mark.parametrize("name", SHIPPED)
def test_shipped_weights_load(name: str) -> None:
    path = shipped_weights(name)
    assert path.stat().st_size < 4_000_000
    with safe_open(str(path), framework="pt") as fh:
        meta = fh.metadata()
    assert json.loads(meta["config"])["name"] == name
    actor, info = load_actor(path)
    assert info["n_updates"] > 0
    assert sum(p.numel() for p in actor.parameters()) > 1000


def test_policy_plan_covers_the_occupancy() -> None:
    occ = make_shape("chair", seed=12345, spacing=2.5).mask
    plan = plan_partition(occ, planner="policy", max_parts=6)
    assert plan.planner == "policy"
    assert 1 <= len(plan.parts) <= 6
    assert plan.covers(occ)
    assert sum(p.voxels for p in plan.parts) == int(occ.sum())
    for part in plan.parts:
        assert all(
            0 <= lo < hi <= n for lo, hi, n in zip(part.box.lo, part.box.hi, occ.shape, strict=True)
        )


def test_policy_with_reconstructor_and_other_weights() -> None:
    from slicerecon.policy.reward import episode_reconstruction

    occ = make_shape("two_spheres", seed=12346, spacing=3.0).mask
    recon, _, _ = episode_reconstruction(occ, 10)
    plan = plan_partition(occ, planner="policy", reconstruct=recon, weights=shipped_weights("il"))
    assert plan.covers(occ)
    with pytest.raises(OptionError):
        plan_partition(occ, planner="heuristic", weights=shipped_weights("il"))


def test_geometry_does_not_import_torch() -> None:
    code = (
        "import sys, slicerecon.partition.planner as p, slicerecon.reconstruct;"
        "assert 'policy' in p.PLANNERS; print('torch' in sys.modules)"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"
    assert "policy" in PLANNERS and np is not None


def test_weights_written_again_to_one_path_are_read_again(tmp_path) -> None:  # noqa: ANN001
    """Actors were cached by path for the whole process: weights trained again into the
    same folder (from a notebook) planned with the old actor, without a word."""
    import os
    import shutil

    from slicerecon.policy.planner import load_policy

    path = tmp_path / "actor.safetensors"
    shutil.copy(shipped_weights("il"), path)
    first, _ = load_policy(path)
    shutil.copy(shipped_weights("ddpg"), path)
    stamp = path.stat().st_mtime_ns + 10**9  # a later write, even on a coarse clock
    os.utime(path, ns=(stamp, stamp))
    second, _ = load_policy(path)
    weights = [dict(a.state_dict()) for a in (first, second)]
    assert any(not (weights[0][k] == weights[1][k]).all() for k in weights[0])
    assert load_policy(path)[0] is second  # unchanged: read once
