"""The batched TorchRL environment: same transitions as PettingZoo, TorchRL's checker, resets."""

from __future__ import annotations

import numpy as np
import pytest

torch = pytest.importorskip("torch")
pytest.importorskip("torchrl")

from torchrl.envs.utils import check_env_specs  # noqa: E402

from marl_cover import parallel_env  # noqa: E402
from marl_cover.agents.training.batched_env import GRAPH_ARRAYS, STATE_KEYS, BatchedCoverageEnv  # noqa: E402

#: A small procedural city with short episodes, so that a few dozen steps cross episode ends.
CONFIG = {"num_robots": 3, "city_size": 60, "hops": 3, "max_steps": 7}


def assert_same_transition(td, envs, returns) -> None:  # noqa: ANN001
    """Sub-environment ``i`` of the TensorDict ``td`` (a reset or a ``"next"`` entry) equals
    ``returns[i]``, what PettingZoo's ``envs[i]`` returned: ``(observations, infos)`` after a
    reset, the five dictionaries after a step."""
    for i, ret in returns.items():
        env = envs[i]
        agents = env.possible_agents
        observations, infos = ret[0], ret[-1]
        for key in GRAPH_ARRAYS:
            expected = np.stack([observations[a][key] for a in agents])
            got = td["robot", "observation", key][i].numpy()
            np.testing.assert_array_equal(got, expected, err_msg=f"env {i} {key}")
        mask = np.stack([observations[a]["action_mask"] for a in agents]).astype(bool)
        np.testing.assert_array_equal(td["robot", "action_mask"][i].numpy(), mask)
        state = env.state()
        for key in STATE_KEYS:
            np.testing.assert_array_equal(td["state", key][i].numpy(), state[key])
        for key in ("new_interest", "total_interest", "blocked", "invalid_action"):
            assert td["robot", "info", key][i].tolist() == [infos[a][key] for a in agents]
        if len(ret) == 5:
            rewards, terminations, truncations = ret[1:4]
            assert td["robot", "reward"][i].flatten().tolist() == [rewards[a] for a in agents]
            terminated, truncated = terminations[agents[0]], truncations[agents[0]]
            assert bool(td["terminated"][i]) == terminated
            assert bool(td["truncated"][i]) == truncated
            assert bool(td["done"][i]) == (terminated or truncated)


def step_both(batched, td, envs, action):  # noqa: ANN001, ANN201
    """Steps the batched env and the PettingZoo envs with the same ``(N, R)`` actions, checks
    that the transitions agree, and returns the batched env's TensorDict."""
    td["robot", "action"] = torch.from_numpy(action)
    td = batched.step(td)
    returns = {
        i: env.step(dict(zip(env.agents, action[i].tolist(), strict=True)))
        for i, env in enumerate(envs)
    }
    assert_same_transition(td["next"], envs, returns)
    return td


@pytest.mark.parametrize(
    ("allow_swaps", "task"), [(True, "coverage"), (False, "coverage"), (True, "exploration")]
)
def test_same_transitions_as_pettingzoo(allow_swaps: bool, task: str) -> None:
    num_envs, seed = 3, 11
    batched = BatchedCoverageEnv(num_envs, allow_swaps=allow_swaps, task=task, **CONFIG)
    batched.set_seed(seed)
    envs = [parallel_env(allow_swaps=allow_swaps, task=task, **CONFIG) for _ in range(num_envs)]
    td = batched.reset()
    assert_same_transition(td, envs, {i: env.reset(seed=seed + i) for i, env in enumerate(envs)})
    rng = np.random.default_rng(0)
    episodes_ended = 0
    for _ in range(24):  # several episode ends, with resets of some sub-environments only
        action = rng.integers(0, 5, size=(num_envs, CONFIG["num_robots"]))
        td = step_both(batched, td, envs, action)
        done = td["next", "done"].flatten()
        episodes_ended += int(done.sum())
        td = batched.step_mdp(td)
        if done.any():
            before = td["robot", "observation"].clone()
            td = batched.reset(td.set("_reset", done.clone().unsqueeze(-1)))
            rows = np.flatnonzero(done.numpy())
            assert_same_transition(td, envs, {i: envs[i].reset() for i in rows})
            kept = ~done
            assert (td["robot", "observation"][kept] == before[kept]).all()
    assert episodes_ended >= num_envs  # every sub-environment ended at least once


@pytest.mark.parametrize("task", ["coverage", "exploration"])
def test_check_env_specs_and_collector(task: str) -> None:
    from torchrl.collectors import Collector

    env = BatchedCoverageEnv(2, task=task, **CONFIG)
    env.set_seed(0)
    check_env_specs(env)
    collector = Collector(env, None, frames_per_batch=40, total_frames=80, return_same_td=True)
    batches = [batch["next", "robot", "reward"].sum().item() for batch in collector]
    collector.shutdown()
    assert len(batches) == 2
    lean = BatchedCoverageEnv(2, observe_robots=False, task=task, **CONFIG)
    check_env_specs(lean)
    assert "observation" not in lean.reset()["robot"]


def test_rollout_is_seeded() -> None:
    def rollout(seed: int) -> torch.Tensor:
        env = BatchedCoverageEnv(2, **CONFIG)
        env.set_seed(seed)
        torch.manual_seed(0)  # random actions come from torch
        data = env.rollout(20, break_when_any_done=False)
        return data["next", "state", "nodes"]

    assert torch.equal(rollout(3), rollout(3))
    assert not torch.equal(rollout(3), rollout(4))


def test_bad_actions_are_named() -> None:
    env = BatchedCoverageEnv(2, **CONFIG)
    td = env.reset()
    td["robot", "action"] = torch.full((2, 3), 7)
    with pytest.raises(ValueError, match=r"\[0, 5\)"):
        env.step(td)
    with pytest.raises(ValueError, match="num_envs"):
        BatchedCoverageEnv(0, **CONFIG)
