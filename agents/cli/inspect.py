"""One robot's ego-graph: its size printed, and a drawing written to a PNG.

Example::

    marl-cover inspect env.map=paper robot=0 steps=5 out=outputs/ego.png
"""

from __future__ import annotations

import sys
from collections.abc import Sequence
from dataclasses import dataclass, field

from marl_cover import EnvSettings, parallel_env
from marl_cover.agents.baselines.greedy import GreedyPolicy
from marl_cover.agents.cli.options import parse
from marl_cover.config import require


@dataclass
class InspectConfig:
    """Which robot, when, and where the drawing goes."""

    robot: int = 0  # index of the ego robot
    seed: int = 0  # the episode's seed
    steps: int = 0  # greedy steps played before inspecting
    out: str = "outputs/ego.png"  # the drawing
    env: EnvSettings = field(default_factory=EnvSettings)

    def __post_init__(self) -> None:
        require(
            (
                0 <= self.robot < self.env.num_robots,
                f"robot must be in [0, {self.env.num_robots}), got {self.robot}",
            ),
            (self.seed >= 0 and self.steps >= 0, "seed and steps must be >= 0"),
        )


def run(config: InspectConfig) -> None:
    """Plays the steps, prints the ego-graph's sizes, draws it."""
    from marl_cover.inspection import draw_ego, ego_to_networkx

    try:
        env = parallel_env(**config.env.as_kwargs())
    except (FileNotFoundError, ValueError) as error:
        raise SystemExit(f"marl-cover inspect: {error}") from None
    hops = config.env.hops
    obs, _ = env.reset(seed=config.seed)
    policy = GreedyPolicy(hops, fallback="random", seed=config.seed)
    for _ in range(config.steps):
        if not env.agents:
            break
        obs, *_ = env.step(policy.act(obs))
    agent = env.possible_agents[config.robot]
    graph = ego_to_networkx(obs[agent])
    kinds = [k for _, k in graph.nodes(data="kind")]
    print(
        f"{agent}: {graph.number_of_nodes()} nodes ({kinds.count('robot')} robots, "
        f"{kinds.count('waypoint')} waypoints, "
        f"{sum(1 for _, f in graph.nodes(data='is_interest') if f)} of interest), "
        f"{graph.number_of_edges()} undirected edges, padded to "
        f"{obs[agent]['nodes'].shape[0]} nodes / {obs[agent]['edge_index'].shape[1]} edges"
    )
    title = f"{agent}, K = {hops}, map {config.env.map}, seed {config.seed}"
    path = draw_ego(obs[agent], config.out, hops=hops, title=title)
    print(f"wrote {path}")


def main(argv: Sequence[str] | None = None, prog: str = "marl-cover inspect") -> None:
    """``marl-cover inspect``: see the module docstring."""
    args = sys.argv[1:] if argv is None else argv
    run(parse(InspectConfig, args, prog=prog, description=__doc__ or ""))
