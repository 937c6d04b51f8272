"""Expert datasets: compact shards, atomic writes, interrupt and resume, exact reload."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from helpers import TINY_DATASET, run_cli

import marl_cover
from marl_cover.agents.experts import RoutingExpert
from marl_cover.agents.training.datasets import (
    Episode,
    load_dataset,
    read_shard,
    record_episode,
    write_shard,
)
from marl_cover.errors import BadFileError, MissingFileError

pytest.importorskip("pyvrp")
ROOT = Path(__file__).resolve().parent.parent
COMMON = [*TINY_DATASET, "workers=1"]


def collect(out: Path, *extra: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [
            sys.executable,
            str(ROOT / "scripts" / "collect.py"),
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
    other = collect(parts, "env.max_steps=20")
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
    with pytest.raises(BadFileError, match=r"shard_00000.npz: not a whole dataset shard"):
        load_dataset(tmp_path)
    with pytest.raises(MissingFileError, match="no dataset shards"):
        load_dataset(tmp_path / "empty")


def open_descriptors() -> int:
    return len(os.listdir("/proc/self/fd"))


def corrupt(path: Path, how: str) -> None:
    """Truncates the file, or flips one byte of its compressed data."""
    data = bytearray(path.read_bytes())
    if how == "truncated":
        path.write_bytes(bytes(data[: len(data) // 2]))
    else:
        data[len(data) // 3] ^= 0x5A
        path.write_bytes(bytes(data))


@pytest.fixture(scope="module")
def clean_dataset(tmp_path_factory) -> Path:
    """Five episodes in three shards, collected once for the corruption tests."""
    out = tmp_path_factory.mktemp("clean") / "data"
    done = collect(out)
    assert done.returncode == 0, done.stderr
    return out


def copy_dataset(source: Path, target: Path) -> Path:
    shutil.copytree(source, target)
    return target


@pytest.mark.skipif(not Path("/proc/self/fd").is_dir(), reason="counts /proc/self/fd (Linux)")
@pytest.mark.parametrize("how", ["truncated", "bit-flipped"])
def test_corrupted_shard_is_named_and_closed(clean_dataset, tmp_path, how: str) -> None:
    data = copy_dataset(clean_dataset, tmp_path / "data")
    shard = data / "shard_00001.npz"
    corrupt(shard, how)
    before = open_descriptors()
    # without the manifest's digest, reading it whole still fails (zip structure or CRC)
    with pytest.raises(BadFileError, match=r"shard_00001.npz: not a whole dataset shard"):
        read_shard(shard)
    # with the manifest, its digest names the expected and the found
    manifest = json.loads((data / "manifest.json").read_text())
    expected = manifest["shards"]["shard_00001.npz"]["sha256"]
    with pytest.raises(
        BadFileError, match=rf"shard_00001.npz: SHA-256 is \w+, the manifest records {expected}"
    ):
        load_dataset(data)
    assert open_descriptors() == before
    with pytest.warns(UserWarning, match="skipped a bad shard: .*shard_00001.npz"):
        kept = load_dataset(data, bad_shards="skip")
    assert [e.seed for e in kept] == [0, 1, 4]


def test_resume_recollects_exactly_the_bad_shard(clean_dataset, tmp_path) -> None:
    data = copy_dataset(clean_dataset, tmp_path / "data")
    corrupt(data / "shard_00001.npz", "bit-flipped")
    refused = collect(data, "bad_shards=raise")
    assert refused.returncode != 0
    assert "shard_00001.npz: SHA-256 is" in refused.stderr
    redone = collect(data)
    assert redone.returncode == 0, redone.stderr
    assert "shard_00001.npz: SHA-256 is" in redone.stdout
    assert "3 shards, 1 to collect" in redone.stdout
    for name in ("manifest.json", "shard_00000.npz", "shard_00001.npz", "shard_00002.npz"):
        assert (data / name).read_bytes() == (clean_dataset / name).read_bytes(), name
    # a shard written but never recorded (killed before the manifest) is collected again
    manifest = json.loads((data / "manifest.json").read_text())
    del manifest["shards"]["shard_00002.npz"]
    (data / "manifest.json").write_text(json.dumps(manifest))
    redone = collect(data)
    assert "shard_00002.npz: not in the manifest" in redone.stdout
    assert (data / "manifest.json").read_bytes() == (clean_dataset / "manifest.json").read_bytes()


class _CentralGreedy:
    """Centralized greedy as a recorder (``act_env``) and a relabeller."""

    def __init__(self, hops: int) -> None:
        from marl_cover.agents.baselines.greedy import CentralizedGreedyPolicy

        self.greedy = CentralizedGreedyPolicy(hops)

    def act_env(self, env) -> dict[str, int]:  # noqa: ANN001
        return dict(zip(env.possible_agents, self.relabel(env, 0).tolist(), strict=True))

    def relabel(self, env, step: int) -> np.ndarray:  # noqa: ANN001
        return np.asarray(self.greedy.act_state(env.state()))


@pytest.mark.parametrize(
    ("argument", "message"),
    [
        ("episodes=0", "episodes and shard_size must be >= 1"),
        ("workers=0", "workers must be >= 1, got 0"),
        ("backend=spark", "backend must be one of ('serial', 'process', 'ray'), got 'spark'"),
        (
            "expert.mode=closed",
            "expert.mode must be one of ('open_loop', 'receding'), got 'closed'",
        ),
        ("expert.backend=gurobi", "expert.backend must be pyvrp or ortools, got 'gurobi'"),
        ("expert.time_limit=0", "expert.time_limit must be > 0, got 0"),
        ("seed=x", "(full_key: seed)"),
        ("env.num_robots=0", "num_robots must be >= 1, got 0"),
    ],
)
def test_collection_names_bad_settings_before_writing(tmp_path, argument, message) -> None:
    result = run_cli("collect", f"out={tmp_path / 'data'}", argument)
    assert result.returncode != 0 and message in result.stderr
    assert "Traceback" not in result.stderr and not (tmp_path / "data").exists()


def test_training_names_the_bad_shard_in_one_line(clean_dataset, tmp_path) -> None:
    data = copy_dataset(clean_dataset, tmp_path / "data")
    corrupt(data / "shard_00002.npz", "truncated")
    done = run_cli("train-bc", f"dataset={data}", f"out={tmp_path / 'bc'}", "env.map=city")
    assert done.returncode != 0 and "Traceback" not in done.stderr
    assert "shard_00002.npz: SHA-256 is" in done.stderr
    assert "collects it again, bad_shards=skip leaves it out" in done.stderr
