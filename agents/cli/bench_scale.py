"""Large teams: environment throughput from 4 to 10,000 robots, beside POGEMA, and the GNN
controller at 1000 robots. Prints a table and writes JSON.

Cases (random actions, resets included; procedural cities of 56.59 waypoints a robot, the
density of the paper's 5659-waypoint map, unless said; one CPU thread):

- ``a``: 1000 robots, 56,590-waypoint city, hops 19: compact and padded observations.
- ``b``: 1000 robots, same city, hops 5, compact and padded, beside POGEMA (1000 agents,
  observation radius 5, 30% obstacles, as many free cells a robot) in the same run.
- ``c``: 100 robots, 5659-waypoint city, hops 5 and 19, compact.
- ``d``: 4 robots, 228-waypoint city, hops 5, compact and padded, beside POGEMA's 4 agents.
- ``e``: hops 5, compact, 100 / 1000 / 10,000 robots (cities up to 565,900 waypoints): the
  spread of agent-steps/s (linear cost: within 2x), and a log-log plot.
- ``g``: the GNN controller at 1000 robots, K = 19 (the shipped model, one pass over the
  team's graph, ``GNNPolicy.act_state``), ms a step, and the peak RSS of a whole episode in a
  fresh process.

Each environment row gives env steps/s and agent-steps/s on one city (resets within it
included) through the PettingZoo API
(``step`` with a dict of actions, observations and infos per agent), the same through the
batch API (``apply_actions`` and ``observe_compact``/``observe_batch``), the bytes of one
step's observations and the median time of a reset that draws a new city. POGEMA
(``pip install pogema==1.4.0``) runs in the interpreter ``pogema_python`` names (a separate
virtualenv: its pins differ from ours), or ``$MARL_COVER_POGEMA_PYTHON``; without one its rows
say so. It runs with random moves, ``on_target="nothing"`` (the team stays whole, as ours),
50-step episodes, resets included.

Example::

    marl-cover bench-scale cases=ab seconds=3 pogema_python=/tmp/pogema/bin/python
"""

from __future__ import annotations

import gc
import json
import os
import subprocess
import sys
import time
from collections.abc import Sequence
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from marl_cover import parallel_env
from marl_cover.agents.cli.options import parse
from marl_cover.agents.io import write_text_atomic
from marl_cover.config import require

#: Waypoints a robot, as on the paper's 5659-waypoint map with 100 robots.
WAYPOINTS_PER_ROBOT = 56.59
#: Targets, by row name: (measure, at least); ``obs_mb`` and ``reset_s`` are upper bounds.
TARGETS: dict[str, dict[str, float]] = {
    "a: 1000 robots, hops 19, compact": {"steps_per_s": 50, "obs_mb": 64, "reset_s": 2},
    "a: 1000 robots, hops 19, padded": {"steps_per_s": 20},
    "b: 1000 robots, hops 5, compact": {"agent_steps_per_s": 200_000},
    "c: 100 robots, hops 5, compact": {"agent_steps_per_s": 250_000},
    "c: 100 robots, hops 19, compact": {"agent_steps_per_s": 50_000},
}
UPPER_BOUNDS = ("obs_mb", "reset_s")
#: Our rows beside POGEMA's and whether the ratio has a target: large teams in compact mode;
#: small teams in the default padded mode (the compact mode is reported beside it).
POGEMA_PAIRS = (
    ("b: 1000 robots, hops 5, compact", "b: 1000 agents, POGEMA, radius 5", True),
    ("d: 4 robots, hops 5, padded", "d: 4 agents, POGEMA, radius 5", True),
    ("d: 4 robots, hops 5, compact", "d: 4 agents, POGEMA, radius 5", False),
)
#: Agent-steps/s from the smallest to the largest team of case e: within this factor.
LINEAR_SPREAD = 2.0
#: The GNN at 1000 robots: ms a step and the episode's peak RSS (MB), at most.
GNN_TARGETS = {"ms_per_step": 100.0, "peak_rss_mb": 2048.0}

_POGEMA = r"""
import json, sys, time
import numpy as np
from pogema import GridConfig, pogema_v0
num_agents, seconds = int(sys.argv[1]), float(sys.argv[2])
size = int(np.ceil(np.sqrt(num_agents * 56.59 / 0.7)))
config = GridConfig(num_agents=num_agents, size=size, density=0.3, obs_radius=5,
                    max_episode_steps=50, seed=0, on_target="nothing")
env = pogema_v0(grid_config=config)
env.reset(seed=0)
rng = np.random.default_rng(0)
steps, start = 0, time.perf_counter()
obs = None
while time.perf_counter() - start < seconds:
    obs, rewards, terminated, truncated, infos = env.step(rng.integers(0, 5, num_agents).tolist())
    steps += 1
    if all(terminated) or all(truncated):
        env.reset()
elapsed = time.perf_counter() - start
print(json.dumps({"steps_per_s": steps / elapsed, "obs_mb": sum(o.nbytes for o in obs) / 1e6,
                  "size": size}))
"""


@dataclass
class BenchScaleConfig:
    """What is timed."""

    cases: str = "abcdeg"  # the cases to run
    seconds: float = 3.0  # timing per row
    resets: int = 3  # resets timed per row (the median is reported)
    largest_team: int = 10_000  # case e's largest team
    gnn_steps: int = 10  # case g: steps timed (after one warm-up step)
    pogema_python: str = ""  # an interpreter with pogema 1.4.0 ("": $MARL_COVER_POGEMA_PYTHON)
    plot: str = "outputs/bench_scale.png"  # case e's log-log plot ("": none)
    out: str = "outputs/bench_scale.json"  # the JSON of every row

    def __post_init__(self) -> None:
        require(
            (
                set(self.cases) <= set("abcdeg"),
                f"cases are letters of 'abcdeg', got {self.cases!r}",
            ),
            (self.seconds > 0, f"seconds must be > 0, got {self.seconds}"),
            (self.resets >= 1, f"resets must be >= 1, got {self.resets}"),
            (self.largest_team >= 1000, f"largest_team must be >= 1000, got {self.largest_team}"),
            (self.gnn_steps >= 1, f"gnn_steps must be >= 1, got {self.gnn_steps}"),
        )


def city_for(num_robots: int) -> int:
    """Waypoints of the city of a team (56.59 a robot)."""
    return round(WAYPOINTS_PER_ROBOT * num_robots)


def measure(env_kwargs: dict[str, Any], seconds: float, resets: int) -> dict[str, Any]:
    """Throughput of one environment through the PettingZoo and the batch API (see the module
    docstring), its observation bytes a step and its median reset time.

    ``env_kwargs`` name a procedural city (``map="city"``, ``city_size``): the reset time is
    that of a reset that draws a new city; the throughput is measured on one city (resets
    within it included), as a grid-world benchmark keeps its grid."""
    from marl_cover.city import CityConfig, generate_city

    env = parallel_env(**env_kwargs)
    reset_times = []
    for seed in range(resets):
        start = time.perf_counter()
        env.reset(seed=seed)
        reset_times.append(time.perf_counter() - start)
    settings = {k: v for k, v in env_kwargs.items() if k not in ("map", "city_size")}
    city = generate_city(np.random.default_rng(0), CityConfig(num_waypoints=env.max_waypoints))
    env = parallel_env(**settings, graph=city)
    env.reset(seed=0)
    compact = env.config.observation_mode == "compact"
    if compact:
        obs_bytes = env.observe_compact().nbytes
    else:
        obs_bytes = sum(int(v.nbytes) for v in env.observe_batch().values())
    num_robots = env.config.num_robots
    rng = np.random.default_rng(0)

    def pettingzoo_step() -> None:
        env.step(dict(zip(env.agents, rng.integers(0, 5, len(env.agents)).tolist(), strict=True)))

    def batch_step() -> None:
        env.apply_actions(rng.integers(0, 5, num_robots))
        env.observe_compact() if compact else env.observe_batch()

    rates = {}
    for api, step in (("pettingzoo", pettingzoo_step), ("batch", batch_step)):
        env.reset(seed=resets)
        for _ in range(5):  # warm-up: first calls, caches
            step()
        env.reset(seed=resets)
        chunks = []  # the median of three timed thirds: one slow spell does not decide
        for _ in range(3):
            gc.collect()
            steps, start = 0, time.perf_counter()
            while time.perf_counter() - start < seconds / 3:
                step()
                steps += 1
                if not env.agents:
                    env.reset()
            chunks.append(steps / (time.perf_counter() - start))
        rates[api] = float(np.median(chunks))
    return {
        "robots": num_robots,
        "waypoints": env.max_waypoints,
        "hops": env.config.hops,
        "mode": env.config.observation_mode,
        "steps_per_s": rates["pettingzoo"],
        "agent_steps_per_s": rates["pettingzoo"] * num_robots,
        "batch_steps_per_s": rates["batch"],
        "batch_agent_steps_per_s": rates["batch"] * num_robots,
        "obs_mb": obs_bytes / 1e6,
        "obs_kb_per_robot": obs_bytes / 1e3 / num_robots,
        "reset_s": float(np.median(reset_times)),
    }


def pogema(num_agents: int, seconds: float, python: str) -> dict[str, Any] | None:
    """POGEMA's agent-steps/s with random moves in the interpreter ``python`` (``None`` when
    there is none, or it has no pogema)."""
    python = python or os.environ.get("MARL_COVER_POGEMA_PYTHON", "")
    if not python:
        return None
    result = subprocess.run(
        [python, "-c", _POGEMA, str(num_agents), str(seconds)],
        capture_output=True,
        text=True,
        check=False,
        env={**os.environ, "OMP_NUM_THREADS": "1"},
    )
    if result.returncode != 0:
        print(f"POGEMA did not run in {python}: {result.stderr.strip()[-300:]}")
        return None
    row = json.loads(result.stdout.strip().splitlines()[-1])
    version = subprocess.run(
        [python, "-c", "import pogema; print(pogema.__version__)"],
        capture_output=True,
        text=True,
        check=False,
    ).stdout.strip()
    return {
        "robots": num_agents,
        "mode": f"pogema {version}",
        "hops": 5,
        "waypoints": None,
        "steps_per_s": row["steps_per_s"],
        "agent_steps_per_s": row["steps_per_s"] * num_agents,
        "obs_mb": row["obs_mb"],
        "obs_kb_per_robot": row["obs_mb"] * 1e3 / num_agents,
        "reset_s": None,
        "grid_size": row["size"],
    }


def env_rows(config: BenchScaleConfig) -> list[dict[str, Any]]:
    """The environment rows of the cases asked for."""
    rows: list[dict[str, Any]] = []

    def add(name: str, **env_kwargs: Any) -> None:
        robots = env_kwargs["num_robots"]
        row = measure(
            {"map": "city", "city_size": city_for(robots), **env_kwargs},
            config.seconds,
            config.resets,
        )
        rows.append({"name": name, **row})
        print(f"{name}: {row['agent_steps_per_s']:,.0f} agent-steps/s", flush=True)

    def add_pogema(name: str, num_agents: int) -> None:
        row = pogema(num_agents, config.seconds, config.pogema_python)
        rows.append({"name": name, **(row or {"mode": "pogema (absent)", "robots": num_agents})})

    if "a" in config.cases:
        for mode in ("compact", "padded"):
            add(f"a: 1000 robots, hops 19, {mode}", num_robots=1000, hops=19, observation_mode=mode)
    if "b" in config.cases:
        for mode in ("compact", "padded"):
            add(f"b: 1000 robots, hops 5, {mode}", num_robots=1000, hops=5, observation_mode=mode)
        add_pogema("b: 1000 agents, POGEMA, radius 5", 1000)
    if "c" in config.cases:
        for hops in (5, 19):
            for mode in ("compact", "padded"):
                add(
                    f"c: 100 robots, hops {hops}, {mode}",
                    num_robots=100,
                    hops=hops,
                    observation_mode=mode,
                )
    if "d" in config.cases:
        for mode in ("compact", "padded"):
            add(
                f"d: 4 robots, hops 5, {mode}",
                num_robots=4,
                hops=5,
                observation_mode=mode,
                city_size=228,
            )
        add_pogema("d: 4 agents, POGEMA, radius 5", 4)
    if "e" in config.cases:
        team = 100
        while team <= config.largest_team:
            add(
                f"e: {team} robots, hops 5, compact",
                num_robots=team,
                hops=5,
                observation_mode="compact",
            )
            team *= 10
    return rows


def gnn_row(config: BenchScaleConfig) -> dict[str, Any]:
    """Case g in a fresh process (its peak RSS is the episode's own)."""
    code = (
        "import json, sys; from marl_cover.agents.cli.bench_scale import gnn_episode; "
        f"print(json.dumps(gnn_episode({config.gnn_steps})))"
    )
    result = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True
    )
    return {
        "name": "g: GNN, 1000 robots, K=19",
        **json.loads(result.stdout.strip().splitlines()[-1]),
    }


def gnn_episode(steps: int) -> dict[str, Any]:
    """The shipped GNN drives 1000 robots on a 56,590-waypoint city for a whole 50-step
    episode; returns the median ms of its ``steps`` timed steps (observation to actions) and
    the process's peak RSS."""
    import resource

    import torch

    from marl_cover.agents.models.checkpoints import load_model
    from marl_cover.agents.models.policy import GNNPolicy
    from marl_cover.agents.models.shipped import model_path

    torch.set_num_threads(1)
    model, _ = load_model(model_path("gnn"))
    policy = GNNPolicy(model, centralized=True)
    env = parallel_env(
        map="city", city_size=city_for(1000), num_robots=1000, hops=model.config.hops
    )
    env.reset(seed=0)
    times, total = [], 0.0
    while env.agents:
        start = time.perf_counter()
        actions = policy.act_state(env.state())
        times.append(time.perf_counter() - start)
        total += float(env.apply_actions(actions).new_interest.sum())
    timed = times[1 : 1 + steps]
    return {
        "robots": 1000,
        "hops": model.config.hops,
        "ms_per_step": 1000 * float(np.median(timed)),
        "peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
        "reward": total,
    }


def checks(rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Each target: the row's figure, the bound, whether it is met."""
    out = []
    by_name = {r["name"]: r for r in rows}
    for name, targets in TARGETS.items():
        if name not in by_name:
            continue
        for measure_name, bound in targets.items():
            value = by_name[name][measure_name]
            upper = measure_name in UPPER_BOUNDS
            out.append(
                {
                    "target": f"{name}: {measure_name} {'<=' if upper else '>='} {bound:g}",
                    "value": value,
                    "met": value <= bound if upper else value >= bound,
                }
            )
    for ours, theirs, targeted in POGEMA_PAIRS:
        if ours in by_name and by_name.get(theirs, {}).get("agent_steps_per_s"):
            ratio = by_name[ours]["agent_steps_per_s"] / by_name[theirs]["agent_steps_per_s"]
            out.append(
                {
                    "target": f"{ours} / POGEMA" + (" >= 1" if targeted else " (no target)"),
                    "value": ratio,
                    "met": ratio >= 1 if targeted else None,
                }
            )
    scaling = [r["agent_steps_per_s"] for r in rows if r["name"].startswith("e:")]
    if len(scaling) > 1:
        spread = max(scaling) / min(scaling)
        out.append(
            {
                "target": f"e: agent-steps/s spread <= {LINEAR_SPREAD:g}x",
                "value": spread,
                "met": spread <= LINEAR_SPREAD,
            }
        )
    for row in rows:
        if row["name"].startswith("g:"):
            for key, bound in GNN_TARGETS.items():
                out.append(
                    {
                        "target": f"g: {key} <= {bound:g}",
                        "value": row[key],
                        "met": row[key] <= bound,
                    }
                )
    return out


def plot_scaling(rows: list[dict[str, Any]], path: str) -> None:
    """Agent-steps/s against the team size, log-log (case e)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    scaling = [r for r in rows if r["name"].startswith("e:")]
    fig, ax = plt.subplots(figsize=(5, 3.5))
    robots = [r["robots"] for r in scaling]
    ax.loglog(robots, [r["agent_steps_per_s"] for r in scaling], "o-", label="PettingZoo API")
    ax.loglog(robots, [r["batch_agent_steps_per_s"] for r in scaling], "s--", label="batch API")
    ax.set_xlabel("robots (cities of 56.59 waypoints a robot)")
    ax.set_ylabel("agent-steps / s")
    ax.set_title("compact observations, hops 5, one CPU thread")
    ax.legend()
    fig.tight_layout()
    os.makedirs(os.path.dirname(path) or ".", exist_ok=True)
    fig.savefig(path, dpi=120)
    plt.close(fig)


def _cell(value: Any, spec: str) -> str:
    return "-" if value is None else format(value, spec)


def run(config: BenchScaleConfig) -> dict[str, Any]:
    """Runs the cases, prints the table, writes the JSON (and the plot)."""
    rows = env_rows(config)
    if "g" in config.cases:
        rows.append(gnn_row(config))
    summary = checks(rows)
    print("| row | steps/s | agent-steps/s | batch agent-steps/s | obs MB / step | reset s |")
    print("|---|---|---|---|---|---|")
    for row in rows:
        if row["name"].startswith("g:"):
            continue
        print(
            f"| {row['name']} | {_cell(row.get('steps_per_s'), ',.1f')} | "
            f"{_cell(row.get('agent_steps_per_s'), ',.0f')} | "
            f"{_cell(row.get('batch_agent_steps_per_s'), ',.0f')} | "
            f"{_cell(row.get('obs_mb'), '.1f')} | {_cell(row.get('reset_s'), '.2f')} |"
        )
    for row in rows:
        if row["name"].startswith("g:"):
            print(
                f"{row['name']}: {row['ms_per_step']:.1f} ms a step, peak RSS "
                f"{row['peak_rss_mb']:.0f} MB, reward {row['reward']:.0f}"
            )
    print("| target | value | met |")
    print("|---|---|---|")
    for check in summary:
        met = {True: "yes", False: "NO", None: "-"}[check["met"]]
        print(f"| {check['target']} | {check['value']:,.2f} | {met} |")
    if config.plot and any(r["name"].startswith("e:") for r in rows):
        plot_scaling(rows, config.plot)
        print(f"wrote {config.plot}")
    record = {"config": asdict(config), "rows": rows, "checks": summary}
    write_text_atomic(config.out, json.dumps(record, indent=1))
    print(f"wrote {config.out}")
    return record


def main(argv: Sequence[str] | None = None, prog: str = "marl-cover bench-scale") -> None:
    """``marl-cover bench-scale``: see the module docstring."""
    args = sys.argv[1:] if argv is None else argv
    run(parse(BenchScaleConfig, args, prog=prog, description=__doc__ or ""))
