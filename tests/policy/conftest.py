"""Policy tests run torch on one thread (the CI machines are small and shared)."""

import pytest
import torch


@pytest.fixture(autouse=True, scope="session")
def _one_thread() -> None:
    torch.set_num_threads(1)
