"""The README's Python snippets are the front door: they run as written, in order, and do what
the text beside them says."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

README = Path(__file__).resolve().parent.parent / "README.md"


def python_blocks() -> list[str]:
    return re.findall(r"```python\n(.*?)```", README.read_text(), flags=re.S)


def test_readme_has_the_usage_snippets() -> None:
    blocks = python_blocks()
    assert len(blocks) == 3
    assert blocks[0].startswith("import marl_cover\n")


@pytest.mark.usefixtures("paper_map_available")
def test_readme_snippets_run() -> None:
    blocks = python_blocks()
    namespace: dict = {}
    exec(compile(blocks[0], "README.md (usage)", "exec"), namespace)
    env = namespace["env"]  # the last one made: 100 robots on the 5659-waypoint map
    assert env.config.map == "paper_large" and len(env.possible_agents) == 100
    assert env.max_waypoints == 5659
    observations, rewards = namespace["observations"], namespace["rewards"]
    assert sorted(observations) == sorted(rewards) == sorted(env.possible_agents)
    for observation in observations.values():
        assert observation["action_mask"].shape == (5,) and observation["action_mask"][0] == 1
    assert namespace["state"]["robot_nodes"].shape == (100,)
    assert set(rewards.values()) == {0}  # everyone stayed: nothing new visited

    exec(compile(blocks[1], "README.md (exploration)", "exec"), namespace)
    env = namespace["env"]
    assert env.config.task == "exploration" and env.config.sensor_range == 22.0
    env.reset(seed=0)
    discovered = env.snapshot().discovered
    assert 0 < discovered.sum() < len(discovered)  # the sensor saw part of the window

    exec(compile(blocks[2], "README.md (quadrotors)", "exec"), namespace)
    env = namespace["env"]
    observations, _ = env.reset(seed=0)
    assert len(observations) == 10 and env.max_waypoints == 1266
    _, rewards, *_ = env.step({agent: 0 for agent in env.agents})
    assert env.time > 0 and np.isfinite(env.positions).all()
    assert sorted(rewards) == sorted(env.possible_agents)
