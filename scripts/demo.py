"""Demo: greedy robots on fresh procedural cities; prints a table and writes a picture.

python scripts/demo.py [--episodes 10] [--robots 4] [--hops 19] [--out outputs/demo]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from agents.evaluation import evaluate  # noqa: E402
from agents.greedy import CentralizedGreedyPolicy, GreedyPolicy  # noqa: E402
from marl_cover import parallel_env  # noqa: E402


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=int, default=10)
    parser.add_argument("--robots", type=int, default=4)
    parser.add_argument("--hops", type=int, default=19)
    parser.add_argument("--city-size", type=int, default=228)
    parser.add_argument("--out", type=Path, default=Path("outputs/demo"))
    args = parser.parse_args()
    env = parallel_env(num_robots=args.robots, hops=args.hops, city_size=args.city_size)
    seeds = range(args.episodes)
    policies = {
        "greedy (each robot on its ego-graph)": GreedyPolicy(args.hops, fallback="random"),
        "greedy (centralized, on state())": CentralizedGreedyPolicy(args.hops, fallback="random"),
    }
    print(
        f"{args.robots} robots, K = {args.hops}, T = {env.config.max_steps}, "
        f"{args.episodes} procedural cities of {args.city_size} waypoints "
        f"(seeds 0..{args.episodes - 1})"
    )
    print(
        f"{'policy':<38} {'reward':>15} {'coverage':>9} {'policy ms/step':>15} {'env ms/step':>12}"
    )
    for name, policy in policies.items():
        s = evaluate(env, policy, seeds)
        print(
            f"{name:<38} {s.mean:7.1f} +- {s.sem:4.1f} {100 * s.mean_coverage:8.1f}% "
            f"{s.controller_ms_per_step:15.2f} {s.env_ms_per_step:12.2f}"
        )

    # one episode drawn: the map, points of interest (orange; green once covered), trails
    import matplotlib

    matplotlib.use("Agg")
    from PIL import Image

    env = parallel_env(
        num_robots=args.robots, hops=args.hops, city_size=args.city_size, render_mode="rgb_array"
    )
    policy = GreedyPolicy(args.hops, fallback="random", seed=0)
    obs, _ = env.reset(seed=0)
    while env.agents:
        obs, *_ = env.step(policy.act(obs))
    args.out.mkdir(parents=True, exist_ok=True)
    path = args.out / "greedy_city.png"
    Image.fromarray(env.render()).save(path)
    env.close()
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
