"""DAgger data from rollouts: a GNN's own episodes, each state labelled by its rollout policy.

The learner (a GNN, argmax; with ``beta``, mixed with the labels) plays the episodes; at every
state each robot gets the move of the one-step rollout policy built on that same GNN
(:class:`agents.rollout.RolloutPolicy`; by default every robot's best single deviation from the
GNN's joint action, ``sequential=False``), and ``accept`` the moves that return as much. The
labels are approximate policy iteration's improved policy: training on them (``python
scripts/train_bc.py ... "dagger.reuse=[OUT]"``) aims the learner at a policy that is better
than itself on its own states (on exploration's windows it did not get there: see
``docs/results/exploration.md``, session 34).

Shards are written atomically (``OUT/shard_NNNNN.npz`` with a ``.json`` of per-episode counts);
the same command resumes, and a saved config that differs (the model's SHA-256 among it) is
refused.
"""

from __future__ import annotations

import json
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from agents.datasets import Episode
from agents.rollout import GNNArgmax, RolloutPolicy
from marl_cover.config import TASKS
from marl_cover.ego import STAY
from marl_cover.env import CoverageEnv


@dataclass
class RolloutLabelConfig:
    """Settings of :func:`collect_rollout_labels`.

    Attributes:
        task: ``"coverage"`` or ``"exploration"``.
        checkpoint: The learner's model file; ``None``: the shipped model of ``task``.
        episodes: Episodes to record.
        seed: First episode seed (consecutive seeds; keep them clear of the evaluation seeds).
        shard_size: Episodes per shard.
        sequential: Label robot by robot (:class:`~agents.rollout.RolloutPolicy`) instead of
            each robot's best deviation from the learner's joint action.
        labels: ``"rollout"``, ``"own"``: the learner's own moves as labels (a control:
            training on those measures what retraining alone does to the learner), or
            ``"local"``: the decentralized rollout's moves, each robot playing its near-ties
            out on its own ego-graph (:class:`~agents.local_rollout.LocalRolloutPolicy`,
            ``margin``; a function of what the learner sees).
        margin: ``labels="local"``: moves within this much of the best logit are played out.
        greedy_after: ``labels="rollout"`` or ``"local"``: greedy plays the play-outs after
            this many steps (``rollout``, coverage only: >= 1, the joint action's step included;
            ``1``: each move then greedy, :func:`agents.greedy.counterfactual_returns`, a few
            hundred times cheaper; ``local``: as ``LocalRolloutPolicy``'s); ``None``: the
            learner to the end.
        beta: Probability that a robot makes its labelled move instead of the learner's at a
            step (DAgger's mixing, drawn from a generator seeded with the episode's seed);
            ``1`` with ``sequential``: the episodes of the rollout policy itself.
        env: ``CoverageConfig`` overrides (``task`` is set from ``task``; ``hops`` defaults to
            the model's).
        out: Output folder.
        progress: Print a line per episode.
    """

    task: str = "coverage"
    checkpoint: str | None = None
    episodes: int = 100
    seed: int = 30_000
    shard_size: int = 5
    sequential: bool = False
    labels: str = "rollout"
    margin: float = 1.0
    greedy_after: int | None = None
    beta: float = 0.0
    env: dict[str, Any] = field(default_factory=lambda: {"map": "paper"})
    out: str = "outputs/rollout_labels"
    progress: bool = True

    def __post_init__(self) -> None:
        if self.task not in TASKS:
            raise ValueError(f"task must be one of {TASKS}, got {self.task!r}")
        if self.episodes < 1 or self.shard_size < 1:
            raise ValueError(
                f"episodes and shard_size must be >= 1, got {self.episodes} and {self.shard_size}"
            )
        if self.labels not in ("rollout", "own", "local"):
            raise ValueError(f"labels must be 'rollout', 'own' or 'local', got {self.labels!r}")
        if not self.margin >= 0:
            raise ValueError(f"margin must be >= 0, got {self.margin}")
        if self.greedy_after is not None and (
            self.labels == "own" or self.greedy_after < (1 if self.labels == "rollout" else 0)
        ):
            raise ValueError(
                f"greedy_after must be >= 1 with labels='rollout' (>= 0 with 'local') and "
                f"unset with 'own', got {self.greedy_after} with {self.labels!r}"
            )
        if self.greedy_after is not None and self.labels == "rollout" and self.task != "coverage":
            raise ValueError(
                f"greedy_after with labels='rollout' plays coverage only, not task={self.task!r}"
            )
        if not 0.0 <= self.beta <= 1.0:
            raise ValueError(f"beta must be in [0, 1], got {self.beta}")
        if "task" in self.env:
            raise ValueError("env.task: set the task with task=, not in env")
        if self.checkpoint and not Path(self.checkpoint).is_file():
            raise FileNotFoundError(f"no model file at {self.checkpoint} (checkpoint)")

    def model_path(self) -> Path:
        """The learner's model file: ``checkpoint``, or the task's shipped model."""
        from agents.models.shipped import shipped_model_path

        return Path(self.checkpoint) if self.checkpoint else shipped_model_path(self.task)


def record_rollout_episode(
    env: CoverageEnv,
    learner: GNNArgmax,
    rollout: Any,
    seed: int,
    beta: float = 0.0,
) -> tuple[Episode, dict[str, Any]]:
    """Plays one episode of ``learner`` (each robot on its label with probability ``beta``)
    and labels each state with ``rollout`` (``None``: with the learner's own moves).

    Returns:
        The episode (the waypoints played, the rollout labels and their ``accept`` sets) and
        its counts: ``total`` (the reward played), ``decisions``, ``changed`` (labels that
        differ from the learner's move) and ``changed_to_stay`` (those of them that stay, action
        0, where the learner moves).
    """
    rng = np.random.default_rng(seed)
    env.reset(seed=seed)
    start = env.snapshot()
    positions, labels, accepts = [start.robot_node.copy()], [], []
    total, changed, changed_to_stay = 0.0, 0, 0
    while env.agents:
        own = learner([env.state()])[0]  # (R,)
        label = own if rollout is None else rollout.improve(env)  # (R,)
        labels.append(label)
        accepts.append(1 << own if rollout is None else rollout.accept.copy())
        differs = label != own  # (R,)
        changed += int(differs.sum())
        changed_to_stay += int((differs & (label == STAY)).sum())
        played = np.where(rng.random(len(own)) < beta, label, own) if beta > 0 else own
        total += float(env.apply_actions(played).new_interest.sum())
        positions.append(env.snapshot().robot_node.copy())
    episode = Episode(
        seed=seed,
        graph=start.graph,
        interest=start.interest.copy(),
        robot_node=np.array(positions, dtype=np.int32),
        actions=np.array(labels, dtype=np.int8),
        accept=np.array(accepts, dtype=np.int8),
    )
    counts = {
        "seed": seed,
        "total": total,
        "decisions": len(labels) * len(own),
        "changed": changed,
        "changed_to_stay": changed_to_stay,
    }
    return episode, counts


def collect_rollout_labels(config: RolloutLabelConfig) -> dict[str, Any]:
    """Records ``config.episodes`` labelled episodes into shards under ``config.out``; shards
    already there are kept. Returns the totals over all shards (also ``summary.json``)."""
    import torch
    import yaml

    import marl_cover
    from agents.cli import file_sha256, write_text_atomic
    from agents.configuration import as_dict
    from agents.datasets import record_shards
    from agents.models.policy import load_model
    from agents.training.runs import check_same_run

    out = Path(config.out)
    out.mkdir(parents=True, exist_ok=True)
    model_path = config.model_path()
    record = {**as_dict(config), "model_sha256": file_sha256(model_path)}
    config_path = out / "config.yaml"
    ignored = ("episodes", "progress", "out")
    check_same_run(config_path, record, ignored, defaults=as_dict(RolloutLabelConfig()))
    write_text_atomic(config_path, yaml.safe_dump(record, sort_keys=False))
    torch.set_num_threads(1)  # tiny tensors: threads only contend (run workers side by side)
    model, _ = load_model(model_path)
    env_options = {"hops": model.config.hops, **config.env, "task": config.task}
    env = marl_cover.parallel_env(**env_options)
    learner = GNNArgmax(model)
    rollout: Any = None
    if config.labels == "rollout":
        rollout = RolloutPolicy(learner, config.sequential, greedy_after=config.greedy_after)
    elif config.labels == "local":
        from agents.local_rollout import LocalRolloutPolicy

        rollout = LocalRolloutPolicy(model, margin=config.margin, greedy_after=config.greedy_after)

    def record_one(seed: int) -> tuple[Episode, dict[str, Any]]:
        started = time.perf_counter()
        episode, counts = record_rollout_episode(env, learner, rollout, seed, config.beta)
        if config.progress:
            print(
                f"episode {seed}: {counts['total']:.0f} points, {counts['changed']} of "
                f"{counts['decisions']} labels differ from the learner's moves "
                f"({counts['changed_to_stay']} to a stay) "
                f"({time.perf_counter() - started:.0f} s)",
                flush=True,
            )
        return episode, counts

    rows = record_shards(out, config.seed, config.episodes, config.shard_size, record_one)
    decisions = sum(r["decisions"] for r in rows)
    changed = sum(r["changed"] for r in rows)
    # shards of older runs lack the stays: their total is unknown (None), not zero
    stays = [r["changed_to_stay"] for r in rows if "changed_to_stay" in r]
    summary = {
        "episodes": len(rows),
        "decisions": decisions,
        "changed": changed,
        "changed_share": changed / max(decisions, 1),
        "changed_to_stay": sum(stays) if len(stays) == len(rows) else None,
        "learner_mean_total": float(np.mean([r["total"] for r in rows])),
    }
    write_text_atomic(out / "summary.json", json.dumps(summary, indent=2))
    return summary
