"""DAgger on mission states: recorded decisions, unlabelled robots, and the collection script."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import torch
from helpers import run_script

from agents.datasets import Episode, read_shard, write_shard
from agents.experts.expert import RoutingExpert
from agents.greedy import GreedyPolicy
from agents.mission import MissionExpert, run_mission
from agents.mission_dagger import NO_LABEL, MissionDaggerConfig, record_mission
from agents.models.gnn import AggregationGNN, GNNConfig
from agents.training.bc import batch_loss
from agents.training.data import GraphTable, episode_transitions
from marl_cover.continuous import QuadrotorCoverageEnv

SMALL = {"map": "city", "num_robots": 3, "city_size": 80, "hops": 6}


def small_env(**dynamics) -> QuadrotorCoverageEnv:
    return QuadrotorCoverageEnv(dynamics={"max_time": 40.0, **dynamics}, **SMALL)


def expert(seed: int) -> MissionExpert:
    return MissionExpert(RoutingExpert(mode="receding", horizon=6, max_iterations=30, seed=seed))


def test_record_labels_only_the_deciding_robots() -> None:
    env = small_env()
    record = record_mission(env, GreedyPolicy(6), expert(2), seed=2, beta=0.0)
    episode = record.episode
    steps, robots = episode.actions.shape
    assert episode.robot_node.shape == (steps + 1, robots)
    labelled = episode.actions != NO_LABEL
    # on arrival every step starts with a robot ready, and at the start all of them are
    assert labelled.any(axis=1).all() and labelled[0].all()
    assert record.labels == int(labelled.sum()) and record.labels < steps * robots
    # a label is among its own equally good moves; unlabelled robots accept nothing
    label_bits = (episode.accept.astype(np.int64) >> episode.actions.clip(min=0)) & 1
    assert np.all(label_bits[labelled] == 1) and np.all(episode.accept[~labelled] == 0)
    assert episode.reward() == record.total
    assert 0 <= record.agreed <= record.labels and record.expert_moves == 0


def test_beta_one_flies_the_expert_mission() -> None:
    """With beta = 1 every decision flies the expert's move: the mission the expert flies."""
    record = record_mission(small_env(), GreedyPolicy(6), expert(4), seed=4, beta=1.0)
    flown = run_mission(small_env(), expert(4), seed=4)
    assert record.total == flown.total and record.episode.num_steps == flown.steps
    assert record.expert_moves == record.labels


def test_record_refuses_states_it_cannot_reproduce() -> None:
    for dynamics, name in (
        ({"retarget": "rate"}, "retarget"),
        ({"observe": "targets"}, "observe"),
        ({"visit_radius": 1.0}, "visit_radius"),
    ):
        with pytest.raises(ValueError, match=f"dynamics.{name}"):
            record_mission(small_env(**dynamics), GreedyPolicy(6), expert(0), seed=0, beta=0.0)
    with pytest.raises(ValueError, match="beta"):
        record_mission(small_env(), GreedyPolicy(6), expert(0), seed=0, beta=1.5)


def test_unlabelled_robots_are_skipped_by_the_loss(tee_graph, tmp_path: Path) -> None:
    positions = np.array([[0, 5], [1, 5], [2, 4]])  # (T + 1, R)
    actions = np.array([[1, NO_LABEL], [NO_LABEL, 1]], dtype=np.int8)
    episode = Episode(
        seed=0,
        graph=tee_graph,
        interest=np.ones(6, dtype=bool),
        robot_node=positions,
        actions=actions,
    )
    np.testing.assert_array_equal(episode.label_sets(), [[2, 0], [0, 2]])
    write_shard(tmp_path / "shard.npz", [episode])
    np.testing.assert_array_equal(read_shard(tmp_path / "shard.npz")[0].actions, actions)
    torch.manual_seed(0)
    model = AggregationGNN(GNNConfig(hops=2))
    table = GraphTable([tee_graph])
    data = episode_transitions([episode], table.max_nodes)
    loss, metrics = batch_loss(model, data, table)
    # the same loss from the two labelled robots' logits alone
    full = episode_transitions(
        [Episode(0, tee_graph, episode.interest, positions, np.ones((2, 2), np.int8))],
        table.max_nodes,
    )
    from agents.models.gnn import action_logits
    from agents.training.data import collate_states

    nodes, edge_index, edge_attr, slots = collate_states(full, table)
    logits = action_logits(model, (nodes, edge_index, edge_attr), slots)  # (2 * R, 5)
    expected = torch.nn.functional.cross_entropy(logits[[0, 3]], torch.tensor([1, 1]))
    assert float(loss.detach()) == pytest.approx(float(expected.detach()), rel=1e-6)
    assert metrics["labelled"] == 2
    none = data.clone()
    none["action"][:] = NO_LABEL
    with pytest.raises(ValueError, match="without any labelled robot"):
        batch_loss(model, none, table)


def test_collect_script_writes_resumable_shards(tmp_path: Path) -> None:
    torch.manual_seed(0)
    model_path = tmp_path / "gnn.pt"
    from agents.models.policy import save_model

    save_model(model_path, AggregationGNN(GNNConfig(hops=3)), {})
    out = tmp_path / "md"
    args = [
        f"checkpoint={model_path}",
        "map=city",
        "num_robots=3",
        "dynamics.max_time=20.0",
        "shard_size=2",
        "expert_horizon=4",
        "expert_iterations=20",
        "seed=7",
        f"out={out}",
    ]
    first = run_script("collect_mission_dagger.py", *args, "missions=2")
    assert first.returncode == 0, first.stderr
    assert sorted(p.name for p in out.glob("shard_*.npz")) == ["shard_00000.npz"]
    made = (out / "shard_00000.npz").stat().st_mtime_ns
    done = run_script("collect_mission_dagger.py", *args, "missions=3")
    assert done.returncode == 0, done.stderr
    assert (out / "shard_00000.npz").stat().st_mtime_ns == made  # kept, not flown again
    episodes = read_shard(out / "shard_00000.npz") + read_shard(out / "shard_00001.npz")
    assert [e.seed for e in episodes] == [7, 8, 9]
    summary = json.loads((out / "summary.json").read_text())
    assert summary["missions"] == 3
    assert summary["labels"] == sum(int((e.actions >= 0).sum()) for e in episodes)
    other = run_script("collect_mission_dagger.py", *args, "missions=3", "beta=0.9")
    assert other.returncode != 0 and "beta" in other.stderr
    assert MissionDaggerConfig(missions=1).mission().methods == ["gnn"]
    missing = run_script(
        "collect_mission_dagger.py", f"out={tmp_path / 'none'}", "checkpoint=no.pt"
    )
    assert missing.returncode != 0 and "Traceback" not in missing.stderr
    assert "collect_mission_dagger: no model file at no.pt (checkpoint)" in missing.stderr
