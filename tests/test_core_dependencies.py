"""``marl_cover`` needs only numpy, scipy, gymnasium and pettingzoo: the environments run, and
a missing optional package is named, in an interpreter where the optional ones cannot be
imported. The baselines (greedy, the routing experts) and their evaluation need no torch."""

from __future__ import annotations

import json
import subprocess
import sys
import textwrap

from helpers import ROOT, run_cli

OPTIONAL = (
    "torch",
    "torchrl",
    "tensordict",
    "ortools",
    "pyvrp",
    "numba",
    "matplotlib",
    "networkx",
    "ray",
)

BLOCKER = textwrap.dedent(
    """
    import importlib.abc
    import sys

    BLOCKED = set(sys.argv[1:])

    class Block(importlib.abc.MetaPathFinder):
        def find_spec(self, name, path=None, target=None):
            if name.split(".")[0] in BLOCKED:
                raise ImportError(f"No module named {name!r} (blocked by the test)")
            return None

    sys.meta_path.insert(0, Block())
    """
)

SCRIPT = BLOCKER + textwrap.dedent(
    """
    import numpy as np
    import pytest
    from pettingzoo.test import parallel_api_test

    import marl_cover

    for task in ("coverage", "exploration"):
        env = marl_cover.parallel_env(task=task, map="city", city_size=90, hops=3, max_steps=8)
        assert env.config.ego_backend == "auto"
        parallel_api_test(env, num_cycles=8)
        observations, _ = env.reset(seed=0)
        while env.agents:
            masks = {a: observations[a]["action_mask"] for a in env.agents}
            observations, *_ = env.step({a: int(np.flatnonzero(m)[-1]) for a, m in masks.items()})
        assert env.state()["nodes"].shape[1] == 4

    quad = marl_cover.quadrotor_parallel_env(map="city", city_size=90, num_robots=3, hops=3)
    observations, _ = quad.reset(seed=0)
    quad.step({a: 0 for a in quad.agents})
    assert quad.config.num_robots == 3

    with pytest.raises(ValueError, match="numba"):
        marl_cover.parallel_env(map="city", ego_backend="numba").reset(seed=0)
    rendered = marl_cover.parallel_env(map="city", render_mode="rgb_array")
    rendered.reset(seed=0)
    with pytest.raises(ImportError, match="rendering needs matplotlib"):
        rendered.render()
    leaked = sorted(m for m in sys.modules if m.split(".")[0] in BLOCKED)
    assert not leaked, leaked
    print("core ok")
    """
)


BASELINES = BLOCKER + textwrap.dedent(
    """
    from marl_cover.agents.cli.main import main

    for args in ARGS:
        main(["evaluate", *args])
    leaked = sorted(m for m in sys.modules if m.split(".")[0] in BLOCKED)
    assert not leaked, leaked
    print("baselines ok")
    """
)


def run_blocked(script: str, *blocked: str) -> subprocess.CompletedProcess:
    """``script`` in a new interpreter at the repository root, ``blocked`` not importable."""
    return subprocess.run(
        [sys.executable, "-c", script, *blocked],
        capture_output=True,
        text=True,
        cwd=ROOT,
        timeout=300,
    )


def test_environments_run_without_the_optional_packages() -> None:
    done = run_blocked(SCRIPT, *OPTIONAL)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip().endswith("core ok")


def test_baselines_are_evaluated_without_torch(tmp_path) -> None:  # noqa: ANN001
    """Greedy and the routing expert, evaluated by ``marl-cover evaluate`` where torch cannot
    be imported, play the episodes they play beside it."""
    runs = {
        "greedy": ["policy=greedy", "env.map=city", "episodes=2"],
        "expert": ["policy=expert", "env.map=city", "episodes=1", "expert.iterations=50"],
    }
    blocked = [[*args, f"out={tmp_path / name}.json"] for name, args in runs.items()]
    done = run_blocked(f"ARGS = {blocked!r}\n" + BASELINES, "torch", "torchrl", "tensordict", "ray")
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip().splitlines()[-1] == "baselines ok"
    for name, args in runs.items():
        beside = run_cli("evaluate", *args, f"out={tmp_path / name}_beside.json")
        assert beside.returncode == 0, beside.stderr
        without = json.loads((tmp_path / f"{name}.json").read_text())["summary"]
        with_torch = json.loads((tmp_path / f"{name}_beside.json").read_text())["summary"]
        rewards = [[r["reward"] for r in s["results"]] for s in (without, with_torch)]
        assert rewards[0] == rewards[1] and len(rewards[0]) == int(
            args[2].removeprefix("episodes=")
        )
