"""Inspect one robot's ego-graph: print its size and draw it to a PNG.

python scripts/inspect_ego.py [--map city|paper|paper_large|PATH] [--hops 19] [--robots 4]
                              [--robot 0] [--seed 0] [--steps 0] [--out outputs/ego.png]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from agents.cli import non_negative_int, positive_int  # noqa: E402
from agents.greedy import GreedyPolicy  # noqa: E402
from marl_cover import parallel_env  # noqa: E402
from marl_cover.inspection import draw_ego, ego_to_networkx  # noqa: E402


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--map", default="city")
    parser.add_argument("--hops", type=positive_int, default=19)
    parser.add_argument("--robots", type=positive_int, default=4)
    parser.add_argument("--robot", type=non_negative_int, default=0, help="index of the ego robot")
    parser.add_argument("--seed", type=non_negative_int, default=0)
    parser.add_argument(
        "--steps", type=non_negative_int, default=0, help="greedy steps before inspecting"
    )
    parser.add_argument("--out", type=Path, default=Path("outputs/ego.png"))
    args = parser.parse_args()
    if not 0 <= args.robot < args.robots:
        parser.error(f"--robot must be in [0, {args.robots})")
    try:
        env = parallel_env(map=args.map, hops=args.hops, num_robots=args.robots)
    except (FileNotFoundError, ValueError) as error:
        parser.error(str(error))
    obs, _ = env.reset(seed=args.seed)
    policy = GreedyPolicy(args.hops, fallback="random", seed=args.seed)
    for _ in range(args.steps):
        if not env.agents:
            break
        obs, *_ = env.step(policy.act(obs))
    agent = env.possible_agents[args.robot]
    graph = ego_to_networkx(obs[agent])
    kinds = [k for _, k in graph.nodes(data="kind")]
    print(
        f"{agent}: {graph.number_of_nodes()} nodes ({kinds.count('robot')} robots, "
        f"{kinds.count('waypoint')} waypoints, "
        f"{sum(1 for _, f in graph.nodes(data='is_interest') if f)} of interest), "
        f"{graph.number_of_edges()} undirected edges, padded to "
        f"{obs[agent]['nodes'].shape[0]} nodes / {obs[agent]['edge_index'].shape[1]} edges"
    )
    path = draw_ego(
        obs[agent],
        args.out,
        hops=args.hops,
        title=f"{agent}, K = {args.hops}, map {args.map}, seed {args.seed}",
    )
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
