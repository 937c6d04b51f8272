"""MAPPO (and IPPO) with TorchRL: a shared GNN actor, a GNN critic.

The loop (TorchRL's multi-agent PPO recipe, ``sota-implementations/multiagent/mappo_ippo.py``):

1. A TorchRL collector steps :class:`~marl_cover.agents.training.batched_env.BatchedCoverageEnv`
   (``num_envs`` episodes together; ``workers > 1`` runs that many in worker processes) with
   the actor, and returns ``frames_per_batch`` env steps per iteration.
2. The reward (``loss.reward``: the team reward, or each robot's own points of interest,
   ``infos["new_interest"]``, which sum to it) is scaled by ``reward_scale``; the episode ends
   are copied onto every robot; TorchRL's GAE gives each robot's advantage and value target
   from the critic.
3. ``epochs`` passes of ``ClipPPOLoss`` over the batch in minibatches (sampled without
   replacement from a TorchRL replay buffer), Adam, gradient clipping.
4. Every ``eval.every`` iterations: the argmax policy on the evaluation seeds through the
   harness, a resumable checkpoint, and ``best.pt`` when the evaluation reward improves.

Actor: the shared aggregation GNN with a masked categorical over each robot's five action
slots. ``model.actor_input="state"`` (default) runs it once per whole-graph state for all
robots, which gives the same logits as running it on each robot's ego-graph (tested) for
about a quarter of the work; ``"ego"`` runs it on the ego-graphs the robots observe. Critic
(``algorithm``): ``"mappo"`` a GNN on ``state`` giving each robot's value (``value_aggregate=
"sum"``: the paper's sum over robots); ``"ippo"`` a GNN on each robot's own ego-graph.

Fine-tuning: ``init`` (a shipped model name or a model file) loads a behaviour-cloned model as
the actor (its GNN config replaces ``model.actor``, or with ``model.grow_actor`` it is first
grown to ``model.actor``: a block per hop, more width or hops, the same policy at the start);
``optim.critic_warmup_iters`` trains only the critic for the first iterations, so that an
untrained critic does not push the cloned policy around; ``model.temperature < 1`` samples
from a sharper policy with the same argmax.

Outputs in ``out``: ``config.yaml``, ``checkpoint.pt`` (resumable: re-run with the same ``out``),
``best.pt`` and ``model.pt`` (actor model files that ``marl-cover evaluate model=...`` reads),
with ``snapshots=true`` the actor at every evaluation as ``steps/step_NNNNNN.pt`` (NNNNNN: the
iteration; ``marl-cover average`` reads them), ``log/`` (TorchRL CSV or TensorBoard logger),
``curve.json`` (per iteration: losses, sampled episode rewards, evaluation reward,
collection/update/wall seconds) and ``summary.json``.
"""

from __future__ import annotations

import json
import logging
import math
import time
from dataclasses import asdict
from pathlib import Path
from typing import Any

import numpy as np
import torch

from marl_cover.agents.cli import options as configuration
from marl_cover.agents.distributed.executor import ray_init
from marl_cover.agents.evaluation.episodes import evaluate
from marl_cover.agents.io import write_text_atomic
from marl_cover.agents.models.checkpoints import load_checkpoint, load_model, save_model
from marl_cover.agents.models.gnn import AggregationGNN
from marl_cover.agents.models.policy import GNNPolicy
from marl_cover.agents.models.shipped import model_path
from marl_cover.agents.training.mappo_config import MAPPOConfig
from marl_cover.agents.training.mappo_parts import (
    build_actor,
    build_critic,
    build_loss,
    episode_rewards,
    make_env,
    prepare_batch,
    resolve_device,
)
from marl_cover.agents.training.runs import check_same_run, make_logger
from marl_cover.env import CoverageEnv

logger = logging.getLogger(__name__)

__all__ = ["MAPPOConfig", "train_mappo"]


def train_mappo(config: MAPPOConfig) -> dict[str, Any]:
    """Trains (or resumes) a MAPPO/IPPO run; returns its summary (see the module docstring)."""
    import yaml
    from torchrl.data import LazyTensorStorage, ReplayBuffer
    from torchrl.data.replay_buffers import SamplerWithoutReplacement

    device = resolve_device(config.device)
    out = Path(config.out)
    out.mkdir(parents=True, exist_ok=True)
    record = configuration.as_dict(config)
    defaults = configuration.as_dict(MAPPOConfig())
    check_same_run(  # a key the saved config lacks (a run from before the key) reads as default
        out / "config.yaml",
        record,
        ignored=("progress", "out", "collector", "snapshots"),
        defaults=defaults,
    )
    write_text_atomic(out / "config.yaml", yaml.safe_dump(record, sort_keys=False))
    torch.manual_seed(config.seed)
    torch.set_num_threads(config.threads)

    eval_env = CoverageEnv(**config.env.as_kwargs())
    num_robots = eval_env.config.num_robots
    actor_gnn = AggregationGNN(config.model.actor)
    metadata: dict[str, Any] = {"algorithm": config.algorithm, "seed": config.seed}
    if config.init is not None:
        actor_gnn, init_meta = load_model(model_path(config.init))
        metadata["init"] = {"path": config.init, **init_meta}
        if config.model.grow_actor:
            actor_gnn = _grown(actor_gnn, config)
    critic_gnn = AggregationGNN(config.model.critic)
    actor_gnn.to(device).train()
    critic_gnn.to(device).train()
    actor = build_actor(actor_gnn, config, num_robots)
    critic = build_critic(critic_gnn, config, num_robots)
    loss_module = build_loss(actor, critic, config)
    critic_lr = config.optim.critic_lr or config.optim.lr
    optimizer = torch.optim.Adam(  # the loss module shares these parameters (tested)
        [
            {"params": list(actor_gnn.parameters()), "lr": config.optim.lr},
            {"params": list(critic_gnn.parameters()), "lr": critic_lr},
        ]
    )
    base_lrs = [config.optim.lr, critic_lr]

    checkpoint_path = out / "checkpoint.pt"
    iteration, best_reward, curve = _resume(
        checkpoint_path, actor_gnn, critic_gnn, optimizer, device
    )

    c = config.collector
    collector: Any = None  # a TorchRL collector, while iterations are left
    connected_ray = False  # whether this run connected to Ray (and so disconnects)
    if iteration < c.n_iters:
        seed = config.seed + 100_003 * iteration
        if c.backend == "ray":  # connected here, disconnected when collection ends
            connected_ray = ray_init(c.ray, c.workers)
        collector = _make_collector(config, actor, device, c.n_iters - iteration, seed)
    buffer = ReplayBuffer(
        storage=LazyTensorStorage(c.frames_per_batch, device=device),
        sampler=SamplerWithoutReplacement(),
        batch_size=config.optim.minibatch_size,
    )
    log = make_logger(config.logger or "none", out)  # (the config turns None into "none")
    progress = None
    if config.progress:
        from tqdm import tqdm

        progress = tqdm(total=c.n_iters, initial=iteration, unit="iter", desc=config.algorithm)
    if iteration == 0 and not curve:  # where training starts (the BC model when fine-tuning)
        reward = _evaluate(eval_env, actor_gnn, config)
        curve.append({"iteration": 0, "frames": 0.0, "observations": 0.0, "eval_reward": reward})
    start_time = time.perf_counter()
    metrics: dict[str, float] = {}
    for data in collector if collector is not None else []:
        collect_seconds = time.perf_counter() - start_time
        rewards = episode_rewards(data)
        # a shallow copy: the collector reuses its buffer, and the keys added here must not stay
        data = prepare_batch(data.copy().to(device), config.loss.reward_scale, config.loss.reward)
        with torch.no_grad():
            loss_module.value_estimator(
                data,
                params=loss_module.critic_network_params,
                target_params=loss_module.target_critic_network_params,
            )
        buffer.empty()
        flat = data.reshape(-1)
        buffer.extend(flat)
        if config.optim.lr_anneal:
            for group, base in zip(optimizer.param_groups, base_lrs, strict=True):
                group["lr"] = base * (1 - iteration / c.n_iters)
        actor_frozen = iteration < config.optim.critic_warmup_iters
        metrics = _update(loss_module, optimizer, buffer, config, actor_frozen)
        collector.update_policy_weights_()
        iteration += 1
        frames = iteration * c.frames_per_batch
        metrics.update(
            {
                "episode_reward": float(np.mean(rewards)) if rewards else math.nan,
                "episodes": float(len(rewards)),
                "frames": float(frames),
                "observations": float(frames * num_robots),
                "collect_seconds": collect_seconds,
                "train_seconds": time.perf_counter() - start_time - collect_seconds,
            }
        )
        if iteration % config.eval.every == 0 or iteration == c.n_iters:
            # one CPU copy for the evaluation, the snapshot, best.pt and the checkpoint
            cpu_actor = _cpu(actor_gnn)
            metrics["eval_reward"] = _evaluate(eval_env, cpu_actor, config)
            if config.snapshots:
                save_model(
                    out / "steps" / f"step_{iteration:06d}.pt",
                    cpu_actor,
                    {**metadata, "iteration": iteration, "eval_reward": metrics["eval_reward"]},
                )
            if metrics["eval_reward"] > best_reward:
                best_reward = metrics["eval_reward"]
                save_model(out / "best.pt", cpu_actor, {**metadata, "iteration": iteration})
        previous_wall = curve[-1].get("wall_seconds", 0.0) if curve else 0.0
        metrics["wall_seconds"] = previous_wall + time.perf_counter() - start_time
        curve.append({"iteration": iteration, **metrics})
        if log is not None:
            for key, value in metrics.items():
                if not math.isnan(value):
                    log.log_scalar(key, value, step=frames)
        if progress is not None:
            progress.update()
            progress.set_postfix(
                reward=f"{metrics['episode_reward']:.1f}",
                eval=f"{metrics.get('eval_reward', math.nan):.1f}",
            )
        if "eval_reward" in metrics:  # every evaluation, the last iteration's included
            save_model(  # a model file (load_model reads the actor) plus the training state
                checkpoint_path,
                cpu_actor,
                {**metadata, "iteration": iteration},
                critic=critic_gnn.state_dict(),
                critic_config=asdict(critic_gnn.config),
                optimizer=optimizer.state_dict(),
                torch_rng=torch.get_rng_state(),
                iteration=iteration,
                best_reward=best_reward,
                curve=curve,
                config=record,
            )
            write_text_atomic(out / "curve.json", json.dumps(curve, indent=1))
        start_time = time.perf_counter()
    if collector is not None:
        collector.shutdown()
        if connected_ray:
            import ray

            ray.shutdown()
    if progress is not None:
        progress.close()
    save_model(out / "model.pt", _cpu(actor_gnn), {**metadata, "iteration": iteration})
    summary = {"iteration": iteration, "best_eval_reward": best_reward, **metadata, **metrics}
    write_text_atomic(out / "summary.json", json.dumps(summary, indent=2, default=str))
    return summary


def _grown(model: AggregationGNN, config: MAPPOConfig) -> AggregationGNN:
    """The init model grown to ``model.actor`` (same logits), or a named error."""
    try:
        return model.grown_to(config.model.actor, seed=config.seed)
    except ValueError as error:
        raise ValueError(
            f"model.grow_actor: cannot grow {config.init} ({model.config}) to model.actor "
            f"({config.model.actor}): {error}"
        ) from error


def _resume(
    path: Path,
    actor_gnn: AggregationGNN,
    critic_gnn: AggregationGNN,
    optimizer: torch.optim.Optimizer,
    device: torch.device,
) -> tuple[int, float, list[dict[str, float]]]:
    """Loads the checkpoint at ``path`` into the networks and the optimiser, if there is one;
    returns the iteration, the best evaluation reward and the learning curve so far."""
    if not path.exists():
        return 0, -math.inf, []
    state = load_checkpoint(path, map_location=device)
    actor_gnn.load_state_dict(state["state_dict"])
    critic_gnn.load_state_dict(state["critic"])
    optimizer.load_state_dict(state["optimizer"])
    torch.set_rng_state(state["torch_rng"])
    logger.info("resumed %s at iteration %d", path.parent, state["iteration"])
    return state["iteration"], state["best_reward"], state["curve"]


def _update(
    loss_module: Any,
    optimizer: Any,
    buffer: Any,
    config: MAPPOConfig,
    actor_frozen: bool,
) -> dict[str, float]:
    """``epochs`` passes of PPO over the buffer; mean losses of the last pass."""
    steps = max(1, len(buffer) // config.optim.minibatch_size)
    totals: dict[str, float] = {}
    for _ in range(config.optim.epochs):
        totals = {}
        for _ in range(steps):
            batch = buffer.sample()
            losses = loss_module(batch)
            if actor_frozen:
                total = losses["loss_critic"]
            else:
                total = losses["loss_objective"] + losses["loss_critic"] + losses["loss_entropy"]
            optimizer.zero_grad()
            total.backward()
            torch.nn.utils.clip_grad_norm_(loss_module.parameters(), config.optim.max_grad_norm)
            optimizer.step()
            keys = ("loss_objective", "loss_critic", "loss_entropy", "entropy", "kl_approx")
            for key in keys:
                if key in losses:
                    totals[key] = totals.get(key, 0.0) + float(losses[key].detach()) / steps
    return totals


def _make_collector(
    config: MAPPOConfig, actor: Any, device: torch.device, n_iters: int, seed: int
) -> Any:
    """A collector whose episodes, the first included, are seeded from ``seed``."""
    from torchrl.collectors import Collector, MultiSyncCollector

    c = config.collector
    total = max(n_iters, 0) * c.frames_per_batch
    kwargs = {
        "frames_per_batch": c.frames_per_batch,
        "total_frames": total,
        "env_device": "cpu",
        "policy_device": device,
        "storing_device": device,
        "auto_register_policy_transforms": False,
    }
    if c.backend == "ray":
        return _ray_collector(config, actor, kwargs, seed)
    if c.workers == 1:  # seeded before the collector's first reset, which it makes when built
        env = make_env(config)
        env.set_seed(seed)
        return Collector(env, actor, return_same_td=True, **kwargs)
    factories = [_EnvFactory(config)] * c.workers
    collector = MultiSyncCollector(factories, actor, **kwargs)
    collector.set_seed(seed)  # seeds the workers' environments, then resets them
    return collector


def _ray_collector(config: MAPPOConfig, actor: Any, kwargs: dict[str, Any], seed: int) -> Any:
    """TorchRL's Ray collection: ``workers`` remote collectors (one CPU each), each with its
    own batched environment, synchronised so that every batch comes from the current policy."""
    from torchrl.collectors import Collector

    c = config.collector
    ray_init(c.ray, c.workers)  # (already connected when train_mappo runs it)
    options = {
        "remote_configs": {"num_cpus": 1, "memory": 2 * 1024**3},
        "collector_kwargs": {"auto_register_policy_transforms": False},
    }
    kwargs = {k: v for k, v in kwargs.items() if k != "auto_register_policy_transforms"}
    collector = Collector(
        [_EnvFactory(config)] * c.workers,
        actor,
        backend="ray",
        sync=True,
        backend_options=options,
        **kwargs,
    )
    collector.set_seed(seed)
    collector.update_policy_weights_()  # the remote collectors start from the learner's weights
    return collector


class _EnvFactory:
    """A picklable ``create_env_fn`` for worker processes."""

    def __init__(self, config: MAPPOConfig) -> None:
        self.config = config

    def __call__(self) -> Any:
        torch.set_num_threads(1)
        return make_env(self.config)


def _evaluate(env: CoverageEnv, gnn: AggregationGNN, config: MAPPOConfig) -> float:
    """Mean reward of the argmax policy (one pass per state) on the evaluation seeds; leaves
    ``gnn`` in training mode."""
    seeds = range(config.eval.seed, config.eval.seed + config.eval.episodes)
    reward = evaluate(env, GNNPolicy(_cpu(gnn), centralized=True), seeds).mean
    gnn.train()
    return reward


def _cpu(gnn: AggregationGNN) -> AggregationGNN:
    """``gnn`` itself on the CPU, or a CPU copy of it."""
    if next(gnn.parameters()).device.type == "cpu":
        return gnn
    copy = AggregationGNN(gnn.config)
    copy.load_state_dict({k: v.cpu() for k, v in gnn.state_dict().items()})
    return copy
