"""DAgger on the mission's own states: flights of the learner, labelled by the routing expert.

The discrete stand-in that the mission GNN learned on moves every robot in lockstep: when the
robots decide, all of them stand on waypoints. In a mission (:mod:`marl_cover.continuous`,
``retarget="arrival"``) the robots reach their targets at different times, and the one that
decides sees the others where they are snapped, some of them mid-hop. :func:`record_mission`
flies a mission with the learner (a mixture with the expert, as in DAgger) and records each
decision's state in the dataset's :class:`agents.datasets.Episode` format, with a label only
for the robots that decide: the others get ``-1`` (no label), which the BC loss skips.

The labeller is the routing expert planning on the target waypoints (:class:`MissionExpert`,
which knows where every robot is bound); a robot that decides is at its target, so its label
is a move from the waypoint its observation is built on.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from agents.datasets import Episode
from agents.mission import MissionConfig, MissionExpert, ask_policy, make_mission_policy
from marl_cover.continuous import DynamicsConfig, QuadrotorCoverageEnv

#: Label of a robot that does not decide at a recorded state (skipped by the BC loss).
NO_LABEL = -1


@dataclass(frozen=True)
class MissionRecord:
    """One recorded mission.

    Attributes:
        episode: The decisions as an :class:`Episode`: ``robot_node (T + 1, R)`` the snapped
            waypoints at each decision (and at the end), ``actions (T, R)`` the expert's labels
            of the deciding robots (``-1`` elsewhere), ``accept (T, R)`` their sets of equally
            good moves (``0`` elsewhere).
        total: Points of interest visited in the mission.
        labels: Robot decisions labelled.
        expert_moves: Decisions that flew the expert's move (the DAgger mixture).
        agreed: Labelled decisions where the learner's move is among the expert's equally
            good moves (``accept``).
    """

    episode: Episode
    total: int
    labels: int
    expert_moves: int
    agreed: int


def record_mission(
    env: QuadrotorCoverageEnv,
    learner: Any,
    expert: MissionExpert,
    seed: int,
    beta: float,
) -> MissionRecord:
    """Flies one mission and records every decision of the robots that are ready.

    Each ready robot flies the expert's move with probability ``beta`` (drawn from a generator
    seeded with ``seed``), the learner's otherwise.

    Args:
        env: The mission's environment (``retarget="arrival"``, ``observe="snapped"``, and the
            default visit radius, so that the visited waypoints are the union of the snapped
            ones the record holds).
        learner: A discrete policy (``act`` or ``act_state``, see :mod:`agents.mission`).
        expert: The labeller.
        seed: Mission seed.
        beta: Probability that a ready robot flies the expert's move.

    Raises:
        ValueError: an environment whose states the record cannot reproduce, naming the setting.
    """
    d = env.dynamics
    for name, value, needed in (
        ("retarget", d.retarget, "arrival"),
        ("observe", d.observe, "snapped"),
        ("visit_radius", d.visit_radius, None),
    ):
        if value != needed:
            raise ValueError(f"record_mission needs dynamics.{name}={needed!r}, got {value!r}")
    if not 0.0 <= beta <= 1.0:
        raise ValueError(f"beta must be in [0, 1], got {beta}")
    rng = np.random.default_rng(seed)
    for policy in (learner, expert):
        if hasattr(policy, "reset"):
            policy.reset(seed)
    observations, _ = env.reset(seed=seed)
    start = env.snapshot()
    agents = env.possible_agents
    rows, labels, accepts = [env.snapped], [], []
    total = expert_moves = agreed = 0
    while env.agents:
        ready = env.ready  # (R,)
        if not np.array_equal(rows[-1][ready], env.targets[ready]):  # rows[-1]: snapped now
            raise RuntimeError("a ready robot is not at its target waypoint")
        wanted = expert.act_env(env)
        label = np.array([wanted[a] for a in agents], dtype=np.int64)  # (R,)
        accept = expert.expert.accept.astype(np.int64)  # (R,) from the targets
        chosen = ask_policy(learner, env, observations)
        learned = np.array([chosen[a] for a in agents], dtype=np.int64)
        take_expert = ready & (rng.random(len(agents)) < beta)
        flown = np.where(take_expert, label, learned)
        expert_moves += int(take_expert.sum())
        agreed += int((ready & ((accept >> learned) & 1 == 1)).sum())
        labels.append(np.where(ready, label, NO_LABEL))
        accepts.append(np.where(ready, accept, 0))
        observations, rewards, *_ = env.step(dict(zip(agents, flown.tolist(), strict=True)))
        total += int(next(iter(rewards.values())))
        rows.append(env.snapped)
    episode = Episode(
        seed=seed,
        graph=start.graph,
        interest=start.interest.copy(),
        robot_node=np.array(rows, dtype=np.int64),
        actions=np.array(labels, dtype=np.int8),
        accept=np.array(accepts, dtype=np.int8),
    )
    if episode.reward() != total:  # the points of the waypoints the record visits
        raise RuntimeError("the record's visited waypoints differ from the mission's")
    labelled = int((episode.actions >= 0).sum())
    return MissionRecord(episode, total, labelled, expert_moves, agreed)


@dataclass
class MissionDaggerConfig:
    """Recorded missions for DAgger (``scripts/collect_mission_dagger.py``).

    Attributes:
        checkpoint: The learner's GNN file (``None``: the shipped mission model).
        gnn_centralized: The learner takes one pass over ``state()`` instead of the ready
            robots' ego-graphs (same actions, tested; faster with many robots ready).
        map: Map preset or grid file (the mission's 1266-waypoint graph).
        num_robots: Team size.
        interest_fraction: Fraction of the waypoints that are points of interest.
        dynamics: The continuous-time mode (``retarget="arrival"``, ``observe="snapped"`` and
            the default visit radius, see :func:`record_mission`).
        missions: Missions to record (seeds ``seed ...``).
        seed: First mission seed (keep clear of the seeds missions are judged on).
        shard_size: Missions per shard (``shard_NNNNN.npz``, written atomically).
        beta: Probability that a ready robot flies the expert's move.
        expert_horizon: Moves the labelling expert plans ahead (receding, blind to the clock).
        expert_iterations: PyVRP iterations per plan (deterministic plans).
        out: Output folder; ``train_bc.py "dagger.reuse=[OUT]"`` trains on it.
        progress: Print a line per mission.
    """

    checkpoint: str | None = None
    gnn_centralized: bool = False
    map: str = "paper_full"
    num_robots: int = 10
    interest_fraction: float = 0.5
    dynamics: DynamicsConfig = field(default_factory=DynamicsConfig)
    missions: int = 20
    seed: int = 9_000_000
    shard_size: int = 5
    beta: float = 0.3
    expert_horizon: int = 29
    expert_iterations: int = 200
    out: str = "outputs/mission_dagger"
    progress: bool = True

    def __post_init__(self) -> None:
        if isinstance(self.dynamics, dict):
            self.dynamics = DynamicsConfig.from_dict(self.dynamics)
        for name, value in (
            ("missions", self.missions),
            ("shard_size", self.shard_size),
            ("expert_horizon", self.expert_horizon),
            ("expert_iterations", self.expert_iterations),
        ):
            if value < 1:
                raise ValueError(f"{name} must be >= 1, got {value}")
        if not 0.0 <= self.beta <= 1.0:
            raise ValueError(f"beta must be in [0, 1], got {self.beta}")
        self.mission()  # names a bad mission setting (a missing checkpoint) on loading

    def mission(self) -> MissionConfig:
        """The mission these records fly (the learner as its GNN)."""
        return MissionConfig(
            map=self.map,
            num_robots=self.num_robots,
            interest_fraction=self.interest_fraction,
            methods=["gnn"],
            checkpoint=self.checkpoint,
            gnn_centralized=self.gnn_centralized,
            dynamics=self.dynamics,
        )


def collect_mission_dagger(config: MissionDaggerConfig) -> dict[str, Any]:
    """Records ``config.missions`` missions into shards under ``config.out``; shards already
    there are kept (a run resumes where it stopped; a saved config that differs, the model's
    SHA-256 among it, is refused). Returns the totals over all shards (also ``summary.json``).
    """
    import json

    import yaml

    from agents.cli import file_sha256, write_text_atomic
    from agents.configuration import as_dict
    from agents.datasets import record_shards
    from agents.experts import RoutingExpert
    from agents.training.runs import check_same_run

    out = Path(config.out)
    out.mkdir(parents=True, exist_ok=True)
    mission = config.mission()
    record = {**as_dict(config), "model_sha256": file_sha256(mission.gnn_model_path())}
    config_path = out / "config.yaml"
    check_same_run(config_path, record, ignored=("missions", "progress", "out"))
    write_text_atomic(config_path, yaml.safe_dump(record, sort_keys=False))
    env = mission.make_env()
    learner = make_mission_policy("gnn", mission)

    def record_one(seed: int) -> tuple[Episode, dict[str, Any]]:
        expert = MissionExpert(
            RoutingExpert(
                mode="receding",
                horizon=config.expert_horizon,
                clock=False,
                max_iterations=config.expert_iterations,
                seed=seed,
            )
        )
        done = record_mission(env, learner, expert, seed, config.beta)
        if config.progress:
            print(
                f"mission {seed}: {done.total} points, {done.labels} labelled decisions, "
                f"learner agrees {done.agreed / max(done.labels, 1):.3f}",
                flush=True,
            )
        return done.episode, {
            "seed": seed,
            "total": done.total,
            "decisions": done.episode.num_steps,
            "labels": done.labels,
            "expert_moves": done.expert_moves,
            "agreed": done.agreed,
        }

    rows = record_shards(out, config.seed, config.missions, config.shard_size, record_one)
    summary = {
        "missions": len(rows),
        "decisions": sum(r["decisions"] for r in rows),
        "labels": sum(r["labels"] for r in rows),
        "agreement": sum(r["agreed"] for r in rows) / max(sum(r["labels"] for r in rows), 1),
        "mean_total": float(np.mean([r["total"] for r in rows])),
    }
    write_text_atomic(out / "summary.json", json.dumps(summary, indent=2))
    return summary
