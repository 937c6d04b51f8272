"""DAgger rounds of behaviour cloning: the learner's roll-outs, every state labelled by the
routing expert (:func:`dagger_round`), and labelled states reused from earlier runs."""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np

from marl_cover.agents.models.gnn import AggregationGNN
from marl_cover.agents.models.policy import GNNPolicy
from marl_cover.agents.training.bc_config import BCConfig, DaggerConfig
from marl_cover.agents.training.datasets import (
    SHARD_PATTERN,
    Episode,
    load_dataset,
    trajectory_ties,
)
from marl_cover.env import CoverageEnv


def dagger_round(
    model: AggregationGNN, env: CoverageEnv, config: BCConfig, round_index: int
) -> list[Episode]:
    """Rolls out the mixed policy and labels every visited state with the expert.

    The open-loop expert re-plans whenever the robots are not where its plan expected, so its
    label at a state the learner led to is the first hop of a fresh plan from that state; the
    receding expert (``dagger.expert_mode``) plans afresh at every state.
    """
    dagger = config.dagger
    beta = dagger.beta * dagger.beta_decay**round_index
    policy = GNNPolicy(model, centralized=True)
    first = dagger.seed + round_index * dagger.episodes
    episodes = []
    for seed in range(first, first + dagger.episodes):
        expert = _routing_expert(dagger, seed)
        rng = np.random.default_rng(seed)
        env.reset(seed=seed)
        start = env.snapshot()
        positions, labels, accepted = [start.robot_node.copy()], [], []
        while env.agents:
            state = env.state()
            label = expert.act_snapshot(env.snapshot())
            accepted.append(expert.accept.copy())
            learner = policy.act_state(state)
            executed = np.where(rng.random(len(label)) < beta, label, learner)
            labels.append(label)
            env.step(dict(zip(env.possible_agents, executed.tolist(), strict=True)))
            positions.append(env.snapshot().robot_node.copy())
        episodes.append(
            Episode(
                seed=seed,
                graph=start.graph,
                interest=start.interest.copy(),
                robot_node=np.array(positions, dtype=np.int64),
                actions=np.array(labels, dtype=np.int8),
                fallbacks=int(expert.counts.get("fallback_steps", 0)),
                accept=np.array(accepted, dtype=np.int8),
            )
        )
    model.train()
    return episodes


def with_ties(episode: Episode) -> Episode:
    """``episode`` with its tie sets (:func:`trajectory_ties`) unless it records its own."""
    if episode.accept is not None:
        return episode
    return dataclasses.replace(episode, accept=trajectory_ties(episode))


def _routing_expert(dagger: DaggerConfig, seed: int) -> Any:
    """The routing expert that labels one roll-out."""
    from marl_cover.agents.experts import RoutingExpert

    return RoutingExpert(
        mode=dagger.expert_mode,
        horizon=dagger.expert_horizon,
        clock=dagger.expert_clock,
        information=dagger.expert_information,
        max_iterations=dagger.iterations,
        seed=seed,
    )


def sensor_range_of(env: CoverageEnv) -> float | None:
    """The range sensor of an exploration env (transitions rebuild what the team discovered),
    ``None`` in coverage."""
    return env.config.sensor_range if env.config.task == "exploration" else None


def reused_episodes(folders: list[str]) -> list[list[Episode]]:
    """The labelled episodes of each ``dagger.reuse`` folder; a clear error for a folder that
    is missing or holds no shards."""
    reused = []
    for folder in folders:
        try:
            reused.append(load_dataset(folder))
        except FileNotFoundError:
            raise FileNotFoundError(
                f"dagger.reuse: {folder} holds no DAgger shards ({SHARD_PATTERN.format(0)}, ...)"
            ) from None
    return reused
