"""Expert datasets: compact shards, atomic writes, interrupt and resume, exact reload."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from helpers import run_script

import marl_cover
from agents.datasets import Episode, load_dataset, read_shard, record_episode, write_shard
from agents.experts import RoutingExpert

pytest.importorskip("pyvrp")
ROOT = Path(__file__).resolve().parent.parent
COMMON = [
    "episodes=5",
    "shard_size=2",
    "city_size=120",
    "max_steps=15",
    "hops=6",
    "iterations=100",
    "workers=1",
]


def collect(out: Path, *extra: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [
            sys.executable,
            str(ROOT / "scripts" / "collect_expert.py"),
            f"out={out}",
            *COMMON,
            *extra,
        ],
        capture_output=True,
        text=True,
        cwd=ROOT,
        timeout=600,
    )


def assert_same_episodes(a: list[Episode], b: list[Episode]) -> None:
    assert [e.seed for e in a] == [e.seed for e in b]
    for x, y in zip(a, b, strict=True):
        assert np.array_equal(x.robot_node, y.robot_node)
        assert np.array_equal(x.actions, y.actions)
        assert np.array_equal(x.interest, y.interest)
        assert np.array_equal(x.graph.neighbors, y.graph.neighbors)
        assert np.array_equal(x.graph.positions, y.graph.positions)


def test_interrupted_collection_resumes_to_the_same_dataset(tmp_path) -> None:
    whole, parts = tmp_path / "whole", tmp_path / "parts"
    assert collect(whole).returncode == 0
    first = collect(parts, "max_shards=1")  # interrupted after one shard
    assert first.returncode == 0, first.stderr
    assert sorted(p.name for p in parts.glob("shard_*.npz")) == ["shard_00000.npz"]
    (parts / ".tmp_half_written.npz").write_bytes(b"partial")  # a crash mid-write
    second = collect(parts)
    assert second.returncode == 0, second.stderr
    assert "2 to collect" in second.stdout
    episodes = load_dataset(parts)
    assert [e.seed for e in episodes] == [0, 1, 2, 3, 4]
    assert_same_episodes(episodes, load_dataset(whole))
    other = collect(parts, "max_steps=20")
    assert other.returncode != 0 and "other settings" in other.stderr


def test_recorded_episode_replays_exactly(tmp_path) -> None:
    env = marl_cover.parallel_env(city_size=120, max_steps=15, hops=6)
    expert = RoutingExpert(time_limit=1.0, max_iterations=100)
    episode = record_episode(env, expert, seed=3)
    write_shard(tmp_path / "shard_00000.npz", [episode])
    (loaded,) = read_shard(tmp_path / "shard_00000.npz")
    assert_same_episodes([loaded], [episode])
    # replaying the stored actions in a fresh env gives the stored positions and observations
    replay = marl_cover.parallel_env(graph=loaded.graph, num_robots=4, max_steps=15, hops=6)
    obs, _ = replay.reset(
        options={
            "robot_nodes": loaded.robot_node[0],
            "interest_nodes": np.flatnonzero(loaded.interest),
        }
    )
    total = 0.0
    for t in range(loaded.num_steps):
        rebuilt = loaded.observations(t, 6, replay._ego_shape, max_steps=15)
        assert set(rebuilt) == set(obs[replay.possible_agents[0]])
        for i, agent in enumerate(replay.possible_agents):
            for key, value in rebuilt.items():
                assert np.array_equal(value[i], obs[agent][key]), (t, agent, key)
        obs, rewards, *_ = replay.step(
            dict(zip(replay.possible_agents, loaded.actions[t].tolist(), strict=True))
        )
        total += rewards["robot_0"]
        assert np.array_equal(replay.snapshot().robot_node, loaded.robot_node[t + 1])
    assert total == loaded.reward()


def test_bad_shard_is_named(tmp_path) -> None:
    bad = tmp_path / "shard_00000.npz"
    bad.write_bytes(b"not a shard")
    with pytest.raises(ValueError, match="shard_00000.npz"):
        load_dataset(tmp_path)
    with pytest.raises(FileNotFoundError, match="no dataset shards"):
        load_dataset(tmp_path / "empty")


class _CentralGreedy:
    """Centralized greedy as a recorder (``act_env``) and a relabeller."""

    def __init__(self, hops: int) -> None:
        from agents.greedy import CentralizedGreedyPolicy

        self.greedy = CentralizedGreedyPolicy(hops)

    def act_env(self, env) -> dict[str, int]:  # noqa: ANN001
        return dict(zip(env.possible_agents, self.relabel(env, 0).tolist(), strict=True))

    def relabel(self, env, step: int) -> np.ndarray:  # noqa: ANN001
        return np.asarray(self.greedy.act_state(env.state()))


def test_label_agreement_replays_recorded_states() -> None:
    from agents.label_agreement import label_agreement

    env = marl_cover.parallel_env(city_size=100, num_robots=3, hops=6, max_steps=12)
    greedy = _CentralGreedy(6)
    episodes = [record_episode(env, greedy, seed) for seed in (4, 5)]
    # A Markov labeller agrees with itself on every replayed state ...
    same = label_agreement(env, episodes, greedy.relabel, 4, np.random.default_rng(0), bucket=5)
    assert (same.agreed, same.total, same.fraction) == (24, 24, 1.0)
    assert sum(total for _, total in same.by_step.values()) == 24
    assert set(same.by_step) <= {0, 5, 10}
    # ... and a labeller that always differs never does; episodes shorter than the sample
    # are taken whole.
    steps_seen = []

    def other(env, step: int) -> np.ndarray:  # noqa: ANN001
        steps_seen.append(step)
        return (greedy.relabel(env, step) + 1) % 5

    none = label_agreement(env, episodes, other, 50, np.random.default_rng(0))
    assert (none.agreed, none.total) == (0, 3 * sum(e.num_steps for e in episodes))
    assert steps_seen == list(range(episodes[0].num_steps)) + list(range(episodes[1].num_steps))
    # Replaying under other settings is an error that names the episode.
    other_env = marl_cover.parallel_env(city_size=101, num_robots=3, hops=6, max_steps=12)
    with pytest.raises(ValueError, match="episode seed 4 left its recorded positions"):
        label_agreement(other_env, episodes, greedy.relabel, 4, np.random.default_rng(0))


def test_label_agreement_replays_dagger_states_and_counts_the_tie_sets() -> None:
    """A DAgger episode's labels are not the moves that were made: the states replay from the
    recorded waypoints, and a relabelling inside the recorded set of equal actions counts."""
    import dataclasses

    from agents.label_agreement import label_agreement, recorded_moves

    env = marl_cover.parallel_env(city_size=100, num_robots=3, hops=6, max_steps=12)
    greedy = _CentralGreedy(6)
    (played,) = [record_episode(env, greedy, 4)]
    moves = recorded_moves(played)
    assert moves.shape == played.actions.shape
    labels = (moves + 1) % 5  # never the move
    tied = dataclasses.replace(played, actions=labels.astype(np.int8), accept=(1 << labels) | 1)
    # relabelling with the moves: never the label, inside the set exactly where it stayed
    result = label_agreement(
        env, [tied], lambda env, step: moves[step], 50, np.random.default_rng(0)
    )
    assert (result.agreed, result.total) == (0, moves.size)
    assert result.in_set == int((moves == 0).sum()) and result.tied == int((labels != 0).sum())
    # relabelling with the labels: all agree, and all lie in the sets
    same = label_agreement(
        env, [tied], lambda env, step: labels[step], 50, np.random.default_rng(0)
    )
    assert same.agreed == same.in_set == moves.size and same.set_fraction == 1.0
    # a recorded jump (not a neighbour) is named
    jump = played.robot_node.copy()
    far = played.graph.hop_distances(jump[2, :1])[0] > 1  # (N,)
    jump[3, 0] = int(np.flatnonzero(far)[0])
    with pytest.raises(ValueError, match="episode seed 4 jumps between waypoints at step 2"):
        recorded_moves(dataclasses.replace(played, robot_node=jump))


def test_a_clock_blind_snapshot_plans_for_the_steps_it_is_told() -> None:
    from agents.experts.problem import build_problem
    from agents.label_agreement import with_steps_left

    env = marl_cover.parallel_env(city_size=100, num_robots=3, hops=6, max_steps=12)
    env.reset(seed=4)
    env.step({a: 0 for a in env.agents})
    snapshot = env.snapshot()
    assert build_problem(snapshot).budget.tolist() == [11, 11, 11]
    blind = with_steps_left(snapshot, 30)
    assert build_problem(blind).budget.tolist() == [30, 30, 30]
    assert np.array_equal(blind.robot_node, snapshot.robot_node)
    with pytest.raises(ValueError, match="steps_left"):
        with_steps_left(snapshot, 0)
    # a receding plan over 30 steps is cut to the 11 left, unless it is blind to the clock
    assert build_problem(snapshot, horizon=30).budget.tolist() == [11, 11, 11]
    assert build_problem(snapshot, horizon=5).budget.tolist() == [5, 5, 5]
    unclocked = build_problem(snapshot, horizon=30, clock=False)
    assert unclocked.budget.tolist() == [30, 30, 30]
    assert np.array_equal(unclocked.distance, build_problem(blind).distance)
    with pytest.raises(ValueError, match="needs a horizon"):
        build_problem(snapshot, clock=False)


def test_label_agreement_script(tmp_path) -> None:
    """Relabels the validation states of a small dataset with the dataset's expert settings."""
    data = tmp_path / "data"
    assert collect(data).returncode == 0
    config = tmp_path / "bc.yaml"
    config.write_text(f"dataset: {data}\nholdout_seeds: [100, 100]\nval_fraction: 0.5\n")
    out = tmp_path / "agreement.json"

    def run(*args: str) -> subprocess.CompletedProcess:
        done = run_script("label_agreement.py", "--config", str(config), "--states", "3", *args)
        assert done.returncode == 0, done.stderr
        return done

    done = run("--out", str(out))
    record = json.loads(out.read_text())
    assert len(record["episodes"]) == 2 and record["total"] == 2 * 3 * 4  # 4 robots
    assert record["expert"] == {"backend": "pyvrp", "time_limit": 0.5, "iterations": 100}
    buckets = list(record["by_step"].values())
    assert [sum(b[0] for b in buckets), sum(b[1] for b in buckets)] == [
        record["agreed"],
        record["total"],
    ]
    assert record["agreement"] == record["agreed"] / record["total"]
    rows = [line.split() for line in done.stdout.splitlines()]
    assert ["all", str(record["agreed"]), str(record["total"])] in [row[:3] for row in rows]
    # The shipped BC model on the same states: the same sampled states, its own agreement.
    gnn_out = tmp_path / "gnn.json"
    run("--relabel", "gnn", "--out", str(gnn_out))
    gnn = json.loads(gnn_out.read_text())
    assert gnn["relabel"] == "gnn" and gnn["checkpoint"].endswith("bc/coverage_gnn.pt")
    assert gnn["episodes"] == record["episodes"] and gnn["total"] == record["total"]
    assert [b[1] for b in gnn["by_step"].values()] == [b[1] for b in buckets]
    # Episodes from a folder of shards, replayed in the config's env, relabelled by the
    # receding expert: the dataset records no tie sets, so the set agreement is the agreement.
    config.write_text(
        f"dataset: {data}\nenv: {{map: city, city_size: 120, max_steps: 15, hops: 6}}\n"
    )
    shards_out = tmp_path / "shards.json"
    done = run(
        "--shards", str(data), "--episodes", "1", "--receding", "6", "--out", str(shards_out)
    )
    shards = json.loads(shards_out.read_text())
    assert shards["dataset"] == str(data) and shards["receding"] == 6
    assert shards["total"] == 3 * 4 and shards["in_set"] == shards["agreed"]
    assert shards["tied"] == 0 and "in set" in done.stdout


@pytest.mark.parametrize(
    ("argument", "message"),
    [
        ("episodes=0", "collect_expert: episodes must be >= 1, got 0"),
        ("workers=0", "collect_expert: workers must be >= 1, got 0"),
        (
            "expert.mode=closed",
            "expert.mode must be one of ('open_loop', 'receding'), got 'closed'",
        ),
        ("expert.backend=gurobi", "expert.backend must be one of ('pyvrp', 'ortools')"),
        ("expert.time_limit=0", "expert.time_limit must be > 0 seconds, got 0"),
        ("seed=x", "CollectOptions.seed must be an integer, got 'x'"),
        ("num_robots=0", "num_robots must be >= 1, got 0"),
    ],
)
def test_collection_names_bad_settings_before_writing(tmp_path, argument, message) -> None:
    result = run_script("collect_expert.py", f"out={tmp_path / 'data'}", argument)
    assert result.returncode != 0 and message in result.stderr
    assert "Traceback" not in result.stderr and not (tmp_path / "data").exists()
