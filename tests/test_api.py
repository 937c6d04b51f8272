"""PettingZoo's and TorchRL's checkers on the environment."""

from __future__ import annotations

import functools
import importlib

import numpy as np
import pytest
from pettingzoo.test import (
    api_test,
    max_cycles_test,
    parallel_api_test,
    parallel_seed_test,
    render_test,
)

import marl_cover

SMALL = {"city_size": 120, "hops": 4}


@pytest.mark.filterwarnings("ignore:reset ignores unknown option")
def test_parallel_api() -> None:
    parallel_api_test(marl_cover.parallel_env(**SMALL), num_cycles=120)


@pytest.mark.filterwarnings("ignore:reset ignores unknown option")
def test_aec_api() -> None:
    api_test(marl_cover.env(**SMALL), num_cycles=60)


def test_parallel_seed() -> None:
    parallel_seed_test(functools.partial(marl_cover.parallel_env, **SMALL), num_cycles=50)


def test_render() -> None:
    import matplotlib

    matplotlib.use("Agg")
    render_test(functools.partial(marl_cover.env, **SMALL))


def test_rgb_array_shows_the_map() -> None:
    env = marl_cover.parallel_env(render_mode="rgb_array", **SMALL)
    env.reset(seed=0)
    frame = env.render()
    assert frame.dtype == np.uint8 and frame.shape[2] == 3
    assert len(np.unique(frame.reshape(-1, 3), axis=0)) > 5  # more than a blank canvas
    env.close()


def test_max_cycles() -> None:
    max_cycles_test(importlib.import_module("marl_cover.env"))


@pytest.mark.parametrize("task", ["coverage", "exploration"])
def test_torchrl_pettingzoo_wrapper_specs(task: str) -> None:
    torch = pytest.importorskip("torch")
    from torchrl.envs.libs.pettingzoo import PettingZooWrapper
    from torchrl.envs.utils import check_env_specs

    torch.manual_seed(0)
    wrapped = PettingZooWrapper(
        marl_cover.parallel_env(task=task, **SMALL), return_state=False, use_mask=False, seed=0
    )
    check_env_specs(wrapped)
    rollout = wrapped.rollout(10)
    assert rollout["robot", "observation", "nodes"].shape[:2] == (10, 4)
    assert rollout["robot", "action_mask"].dtype == torch.bool
