"""Behaviour cloning of the routing expert, with DAgger as an option.

The recipe (defaults: the paper's, the paper's code, except that every recorded
episode is used instead of the first 200):

1. Load the expert dataset; drop the episodes whose seeds are held out for evaluation
   (``holdout_seeds``: the harness's seeds 0..99 are also dataset seeds); split the rest by
   episode into train and validation.
2. Store the transitions in a TorchRL replay buffer (``LazyTensorStorage``, sampling without
   replacement: epochs) and collate each batch into one flat graph of whole-graph states.
3. Minimise the cross-entropy of the expert's action over every robot of the batch (minus
   ``entropy_coef`` times the entropy), Adam, learning rate ``lr * lr_decay ** (step /
   lr_decay_every)``.
4. Every ``val_every`` steps: validation cross-entropy and accuracy, the mean reward of the
   greedy (argmax) policy on ``select_episodes`` selection episodes (seeds from
   ``select_seed``, disjoint from the dataset and the test seeds), a resumable checkpoint,
   ``best.pt`` when the selection reward improves, and (``snapshots``) the model as
   ``steps/step_NNNNNN.pt``, so that a longer evaluation can choose among them afterwards.
5. DAgger (``dagger.rounds > 0``; ``init`` and ``steps=0`` run it from an earlier model):
   play the current policy (executing the expert's action with probability ``beta``,
   decaying per round), label every visited state with the expert re-planned from that state
   (or, ``dagger.expert_mode=receding``, a receding-horizon expert, blind to the clock with
   ``dagger.expert_clock=false``), add the labelled states to the buffer (and to disk, as
   dataset shards), and train ``dagger.steps`` more steps with a fresh learning-rate schedule.
   With ``dagger.fraction`` the labelled states have a buffer of their own and fill that share
   of every batch (otherwise they are a few percent of the transitions).

Resuming: ``checkpoint.pt`` holds the model, the optimiser, the sampler, the RNG states and the
phase; DAgger rounds already labelled are read back from ``out/dagger``. A finished run
resumed with more ``dagger.rounds`` (or a copy of its folder under another ``out``) goes on
with the next round, as one longer run would have.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch
from torch.nn import functional

from marl_cover.agents.cli import options as configuration
from marl_cover.agents.evaluation.episodes import evaluate
from marl_cover.agents.io import write_text_atomic
from marl_cover.agents.models.checkpoints import load_checkpoint, load_model, save_model
from marl_cover.agents.models.gnn import AggregationGNN
from marl_cover.agents.models.logits import action_logits
from marl_cover.agents.models.policy import GNNPolicy
from marl_cover.agents.models.shipped import model_path
from marl_cover.agents.training.bc_config import BCConfig, DaggerConfig
from marl_cover.agents.training.dagger import (
    dagger_round,
    reused_episodes,
    sensor_range_of,
    with_ties,
)
from marl_cover.agents.training.data import GraphTable, collate_states, episode_transitions
from marl_cover.agents.training.datasets import (
    SHARD_PATTERN,
    Episode,
    ShardManifest,
    load_dataset,
    read_shard,
    write_shard,
)
from marl_cover.agents.training.runs import check_same_run, make_logger
from marl_cover.ego import NUM_ACTIONS
from marl_cover.env import CoverageEnv

logger = logging.getLogger(__name__)

__all__ = ["BCConfig", "DaggerConfig", "train_bc"]


def read_dagger_rounds(manifest: ShardManifest, rounds: int) -> list[list[Episode]]:
    """The DAgger rounds a resumed run already played (their shards, checked against the
    folder's manifest where it records them).

    Raises:
        BadFileError: a round's shard is corrupted, naming it (delete it to play the round
            again).
    """
    played = []
    for k in range(rounds):
        path = manifest.folder / SHARD_PATTERN.format(k)
        if path.exists():
            digest = manifest.shards.get(path.name, {}).get("sha256")
            played.append(read_shard(path, digest))
    return played


def split_episodes(config: BCConfig) -> tuple[list[Episode], list[Episode]]:
    """Train and validation episodes of the dataset (held-out seeds removed, split by episode)."""
    first, stop = config.holdout_seeds
    dataset = load_dataset(config.dataset, config.bad_shards)
    episodes = [e for e in dataset if not first <= e.seed < stop]
    if config.max_episodes is not None:
        episodes = episodes[: config.max_episodes]
    if len(episodes) < 2:
        raise ValueError(
            f"{config.dataset}: {len(episodes)} usable episodes, need >= 2 (episodes with "
            f"seeds in holdout_seeds [{first}, {stop}) are held out for evaluation)"
        )
    order = np.random.default_rng(config.seed).permutation(len(episodes))
    num_val = max(1, round(config.val_fraction * len(episodes)))
    val = [episodes[i] for i in sorted(order[:num_val])]
    train = [episodes[i] for i in sorted(order[num_val:])]
    return train, val


def make_buffer(capacity: int, batch_size: int | None = None) -> Any:
    """A TorchRL replay buffer sampling stored transitions without replacement (epochs)."""
    from torchrl.data import LazyTensorStorage, ReplayBuffer
    from torchrl.data.replay_buffers import SamplerWithoutReplacement

    return ReplayBuffer(
        storage=LazyTensorStorage(capacity),
        sampler=SamplerWithoutReplacement(),
        batch_size=batch_size,
    )


def mixed_batch(dataset: Any, own: Any | None, batch_size: int, own_size: int) -> Any:
    """``batch_size`` transitions: ``own_size`` from the DAgger buffer ``own`` (last) and the
    rest from ``dataset``; all from ``dataset`` while ``own`` is absent or empty."""
    if own is None or len(own) == 0:
        return dataset.sample(batch_size)
    return torch.cat([dataset.sample(batch_size - own_size), own.sample(own_size)])


@dataclass
class Part:
    """Transitions collated together: one padding, one team size, one episode length."""

    batch: Any
    table: GraphTable
    max_steps: int | None = None


def batch_loss(
    model: AggregationGNN,
    batch: Any,
    table: GraphTable,
    entropy_coef: float = 0.0,
    max_steps: int | None = None,
    extra: Part | None = None,
    ties: bool = False,
) -> tuple[torch.Tensor, dict[str, float]]:
    """Mean cross-entropy of the expert's actions over every robot of a batch of transitions
    (``max_steps``: actions per episode, for a model that reads the time), and of the ``extra``
    transitions collated apart (DAgger states of another map or team size).

    With ``ties`` the loss is instead the negative log-probability of the set of actions the
    expert rated as good as its label (the transitions' ``accept`` bit masks): a learner is not
    pushed toward the expert's tie-break between equally short paths. The metrics hold both,
    and the accuracy of the argmax against the label and against the set."""
    parts = [Part(batch, table, max_steps)] + ([] if extra is None else [extra])
    logit_parts, targets, accepts = [], [], []
    for part in parts:
        nodes, edge_index, edge_attr, action_edges = collate_states(
            part.batch, part.table, model.config.time_horizon, part.max_steps
        )
        logit_parts.append(action_logits(model, (nodes, edge_index, edge_attr), action_edges))
        targets.append(part.batch["action"].reshape(-1))
        accepts.append(part.batch["accept"].reshape(-1))
    logits, target, accept = torch.cat(logit_parts), torch.cat(targets), torch.cat(accepts)
    # robots without a label (-1: they did not decide at that state) do not count
    labelled = target >= 0  # (B*R,)
    if not bool(labelled.any()):
        raise ValueError("a batch without any labelled robot (every action is -1)")
    if not bool(labelled.all()):
        logits, target, accept = logits[labelled], target[labelled], accept[labelled]
    accepted = (accept.unsqueeze(-1) >> torch.arange(NUM_ACTIONS)) & 1  # (L, 5)
    cross_entropy = functional.cross_entropy(logits, target)
    log_probs = torch.log_softmax(logits, dim=-1)
    # -log of the probability of the accepted set (the label alone where there are no ties)
    set_nll = -torch.logsumexp(log_probs.masked_fill(accepted == 0, -math.inf), dim=-1).mean()
    probs = log_probs.exp()
    entropy = -(probs * log_probs.masked_fill(probs == 0, 0.0)).sum(-1).mean()
    loss = (set_nll if ties else cross_entropy) - entropy_coef * entropy
    choice = logits.argmax(-1, keepdim=True)
    return loss, {
        "cross_entropy": float(cross_entropy.detach()),
        "set_nll": float(set_nll.detach()),
        "entropy": float(entropy.detach()),
        "accuracy": float((choice.squeeze(-1) == target).float().mean()),
        "set_accuracy": float(accepted.gather(-1, choice).float().mean()),
        "labelled": int(labelled.sum()),
    }


@torch.no_grad()
def validate(
    model: AggregationGNN,
    data: Any,
    table: GraphTable,
    chunk: int = 512,
    max_steps: int | None = None,
) -> dict:
    """Cross-entropy and accuracy over all validation transitions, against the labels and
    against the sets of equally good actions (``set_nll``, ``set_accuracy``)."""
    model.eval()
    totals = {"cross_entropy": 0.0, "accuracy": 0.0, "set_nll": 0.0, "set_accuracy": 0.0}
    for start in range(0, len(data), chunk):
        batch = data[start : start + chunk]
        _, metrics = batch_loss(model, batch, table, max_steps=max_steps)
        for key in totals:
            totals[key] += metrics[key] * len(batch)
    model.train()
    return {f"val_{key}": value / len(data) for key, value in totals.items()}


def selection_reward(model: AggregationGNN, env: CoverageEnv, config: BCConfig) -> float:
    """Mean reward of the argmax policy (centralized pass) on the selection episodes."""
    seeds = range(config.select_seed, config.select_seed + config.select_episodes)
    summary = evaluate(env, GNNPolicy(model, centralized=True), seeds)
    model.train()
    return summary.mean


# ---------------------------------------------------------------------------- checkpoints
def _phase(step: int, config: BCConfig) -> tuple[int, int]:
    """(phase, step within the phase): phase 0 is BC, phase k the training after round k."""
    if step < config.steps or config.dagger.rounds == 0:
        return 0, step
    offset = step - config.steps
    return 1 + offset // config.dagger.steps, offset % config.dagger.steps


# ---------------------------------------------------------------------------- the loop
def train_bc(config: BCConfig) -> dict[str, Any]:
    """Trains (or resumes) a behaviour-cloned GNN; returns a summary of the run.

    Writes ``out/config.yaml``, ``out/checkpoint.pt`` (resumable), ``out/best.pt`` (best
    selection reward), ``out/model.pt`` (final weights), ``out/log/`` (TorchRL logger) and
    ``out/summary.json``.
    """
    import json

    import yaml

    out = Path(config.out)
    out.mkdir(parents=True, exist_ok=True)
    record = configuration.as_dict(config)
    config_path = out / "config.yaml"
    # more DAgger rounds continue a finished run (the rounds done are read back from disk)
    check_same_run(
        config_path,
        record,
        ignored=("progress", "out", "steps", "snapshots", "dagger.rounds"),
        defaults=configuration.as_dict(BCConfig()),
    )
    write_text_atomic(config_path, yaml.safe_dump(record, sort_keys=False))

    # seeding: torch (initialisation, sampling order) and numpy (split) from one seed
    torch.manual_seed(config.seed)
    torch.set_num_threads(config.threads)

    train, val = split_episodes(config)
    if config.ties:  # the expert's own trajectories show which other moves were as good
        train, val = ([with_ties(e) for e in part] for part in (train, val))
    env = CoverageEnv(**config.env.as_kwargs())
    max_nodes = max([e.graph.num_nodes for e in train + val] + [env.max_waypoints])
    dagger_manifest = ShardManifest(out / "dagger")
    dagger_episodes = read_dagger_rounds(dagger_manifest, config.dagger.rounds)
    reused = reused_episodes(config.dagger.reuse)
    table = GraphTable([e.graph for e in train + val], max_nodes)
    # exploration: transitions carry what the team had discovered (same sensor as the env)
    sensor = sensor_range_of(env)
    val_data = episode_transitions(val, max_nodes, first_index=len(train), sensor_range=sensor)
    settings = config.env.as_kwargs()
    select_env = CoverageEnv(**{**settings, **config.select_env}) if config.select_env else env
    # dagger.env: roll-outs on another map or team, their states collated apart
    apart = bool(config.dagger.env)
    rollout_env = CoverageEnv(**{**settings, **config.dagger.env}) if apart else env
    rollout_steps, rollout_sensor = rollout_env.config.max_steps, sensor_range_of(rollout_env)
    own_table: GraphTable | None = None
    dagger_capacity = config.dagger.rounds * config.dagger.episodes * rollout_steps
    dagger_capacity += sum(e.num_steps for episodes in reused for e in episodes)
    # with dagger.fraction the DAgger states have a buffer of their own, drawn from at that rate
    fraction = config.dagger.fraction
    own_size = 0 if fraction is None else max(1, round(fraction * config.batch_size))
    own = make_buffer(max(dagger_capacity, 1)) if fraction is not None else None
    buffer = make_buffer(sum(e.num_steps for e in train) + (dagger_capacity if own is None else 0))
    buffer.extend(episode_transitions(train, max_nodes, sensor_range=sensor))

    def add_dagger(episodes: list[Episode]) -> None:
        nonlocal table, own_table
        graphs = [e.graph for e in episodes]
        if apart:  # the roll-out env's graphs, padded to its largest map
            assert own is not None  # dagger.env requires dagger.fraction (DaggerConfig)
            if own_table is None:
                first, own_table = 0, GraphTable(graphs, rollout_env.max_waypoints)
            else:
                first, own_table = len(own_table), own_table.extended(graphs)
            own.extend(
                episode_transitions(
                    episodes, own_table.max_nodes, first_index=first, sensor_range=rollout_sensor
                )
            )
            return
        first = len(table)
        table = table.extended(graphs)
        (buffer if own is None else own).extend(
            episode_transitions(episodes, max_nodes, first_index=first, sensor_range=sensor)
        )

    def next_batch() -> tuple[Any, Part | None]:
        if not apart or own is None or own_table is None or len(own) == 0:
            return mixed_batch(buffer, own, config.batch_size, own_size), None
        extra = Part(own.sample(own_size), own_table, rollout_steps)
        return buffer.sample(config.batch_size - own_size), extra

    for episodes in reused + dagger_episodes:
        add_dagger(episodes)

    model = AggregationGNN(config.model)
    if config.init is not None:
        start, _ = load_model(model_path(config.init))
        try:  # a block per hop or more width start from the init model's function
            start = start.grown_to(config.model, seed=config.seed)
        except ValueError:
            raise ValueError(
                f"init {config.init} is a {start.config}, not model {config.model} "
                "(nor one that can grow into it)"
            ) from None
        model.load_state_dict(start.state_dict())
    optimizer = torch.optim.Adam(model.parameters(), lr=config.lr)
    step, best_reward = 0, -math.inf
    checkpoint_path = out / "checkpoint.pt"
    if checkpoint_path.exists():
        state = load_checkpoint(checkpoint_path)
        model.load_state_dict(state["state_dict"])
        optimizer.load_state_dict(state["optimizer"])
        buffer.sampler.load_state_dict(state["sampler"])
        if own is not None:
            own.sampler.load_state_dict(state["dagger_sampler"])
        torch.set_rng_state(state["torch_rng"])
        step, best_reward = state["step"], state["best_reward"]
        logger.info("resumed %s at step %d", out, step)
    log = make_logger(config.logger, out)
    metadata = {
        "dataset": config.dataset,
        "train_episodes": len(train),
        "val_episodes": len(val),
        "seed": config.seed,
    }

    progress = None
    if config.progress:
        from tqdm import tqdm

        progress = tqdm(total=config.total_steps, initial=step, unit="batch", desc="bc")
    model.train()
    metrics: dict[str, float] = {}
    while step < config.total_steps:
        phase, phase_step = _phase(step, config)
        if phase > 0 and phase_step == 0 and len(dagger_episodes) < phase:
            episodes = dagger_round(model, rollout_env, config, phase - 1)
            name = SHARD_PATTERN.format(phase - 1)
            digest = write_shard(dagger_manifest.folder / name, episodes)
            dagger_manifest.add(name, digest, [e.seed for e in episodes])
            dagger_episodes.append(episodes)
            add_dagger(episodes)
            reward = float(np.mean([e.reward() for e in episodes]))
            if log is not None:
                log.log_scalar("dagger_rollout_reward", reward, step=step)
        for group in optimizer.param_groups:
            group["lr"] = config.lr * config.lr_decay ** (phase_step / config.lr_decay_every)
        batch, extra = next_batch()
        loss, metrics = batch_loss(
            model,
            batch,
            table,
            config.entropy_coef,
            env.config.max_steps,
            extra=extra,
            ties=config.ties,
        )
        optimizer.zero_grad()
        loss.backward()
        optimizer.step()
        step += 1
        if progress is not None:
            progress.update()
            progress.set_postfix(ce=f"{metrics['cross_entropy']:.3f}")
        if log is not None and step % 50 == 0:
            for key, value in metrics.items():
                log.log_scalar(f"train_{key}", value, step=step)
            log.log_scalar("lr", optimizer.param_groups[0]["lr"], step=step)
        if step % config.val_every == 0 or step == config.total_steps:
            scores = validate(model, val_data, table, max_steps=env.config.max_steps)
            scores["select_reward"] = selection_reward(model, select_env, config)
            if config.snapshots:
                snapshot = out / "steps" / f"step_{step:06d}.pt"
                save_model(snapshot, model, {**metadata, "step": step, **scores})
            if scores["select_reward"] > best_reward:
                best_reward = scores["select_reward"]
                save_model(out / "best.pt", model, {**metadata, "step": step, **scores})
            if log is not None:
                for key, value in scores.items():
                    log.log_scalar(key, value, step=step)
            metrics.update(scores)
            logger.info("step %d: %s", step, scores)
            if progress is not None:
                progress.write(
                    f"step {step}: " + ", ".join(f"{k} {v:.4f}" for k, v in scores.items())
                )
            save_model(  # a model file (load_model reads it) plus the training state
                checkpoint_path,
                model,
                {**metadata, "step": step},
                optimizer=optimizer.state_dict(),
                sampler=buffer.sampler.state_dict(),
                dagger_sampler=None if own is None else own.sampler.state_dict(),
                torch_rng=torch.get_rng_state(),
                step=step,
                best_reward=best_reward,
                config=record,
            )
    if progress is not None:
        progress.close()
    save_model(out / "model.pt", model, {**metadata, "step": step})
    summary = {"step": step, "best_select_reward": best_reward, **metadata, **metrics}
    write_text_atomic(out / "summary.json", json.dumps(summary, indent=2))
    return summary
