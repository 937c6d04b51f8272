"""``marl_cover`` needs only numpy, scipy, gymnasium and pettingzoo: the environments run, and
a missing optional package is named, in an interpreter where the optional ones cannot be
imported."""

from __future__ import annotations

import subprocess
import sys
import textwrap

from helpers import ROOT

OPTIONAL = ("torch", "torchrl", "tensordict", "ortools", "pyvrp", "numba", "matplotlib", "networkx")

SCRIPT = textwrap.dedent(
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


def test_environments_run_without_the_optional_packages() -> None:
    done = subprocess.run(
        [sys.executable, "-c", SCRIPT, *OPTIONAL],
        capture_output=True,
        text=True,
        cwd=ROOT,
        timeout=300,
    )
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip().endswith("core ok")
