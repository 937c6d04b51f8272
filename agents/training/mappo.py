"""MAPPO (and IPPO) for the coverage task with TorchRL: a shared GNN actor, a GNN critic.

The loop (TorchRL's multi-agent PPO recipe, ``sota-implementations/multiagent/mappo_ippo.py``):

1. A TorchRL collector steps :class:`~agents.batched_env.BatchedCoverageEnv` (``num_envs``
   episodes together; ``workers > 1`` runs that many in worker processes) with the actor, and
   returns ``frames_per_batch`` env steps per iteration.
2. The reward (``loss.reward``: the team reward, or each robot's own points of interest,
   ``infos["new_interest"]``, which sum to it) is scaled by ``reward_scale``; the episode ends
   are copied onto every robot; TorchRL's GAE gives each robot's advantage and value target
   from the critic. With ``loss.advantage="counterfactual"`` (coverage) the advantage is
   simulated instead: the environment plays greedy out after every robot's every move, the
   others on the moves they took (:func:`agents.greedy.counterfactual_returns`, a compiled
   play-out of tens of microseconds), and a robot's advantage is its move's return minus the
   sampling policy's mean over its moves (:func:`counterfactual_advantages`; COMA's
   counterfactual baseline, with the values played out instead of learned). The critic still
   trains, and is not used. ``loss.all_actions`` takes PPO's clipped surrogate in expectation
   over each robot's moves (:func:`all_action_objective`), so that every move's value counts
   at every state, not only the sampled move's.
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
``model.critic_time``: the critic also reads the actions left in the episode (``state``'s
``steps_left``, as one more node feature), and the end of an episode at ``max_steps`` counts as
terminal in GAE (nothing is collected after it, so its value is not bootstrapped). Without it
the critic cannot tell the start of an episode from its end on the same graph.
``model.critic_input="privileged"`` (MAPPO): the critic reads the true map instead of
``state`` (:meth:`marl_cover.CoverageEnv.privileged_state`: in exploration every waypoint,
discovered or not, and every unvisited point of interest), an asymmetric actor-critic: the
actor still sees only what the robots see, and the critic, used only in training, values a
state by what lies beyond the discovered map too.

Fine-tuning: ``init`` loads a behaviour-cloned model as the actor (its GNN config replaces
``model.actor``, or with ``model.grow_actor`` it is first grown to ``model.actor``: a block per
hop, more width or hops, the same policy at the start); ``optim.critic_warmup_iters`` trains only
the critic for the first iterations, so that an untrained critic does not push the cloned policy
around; ``model.temperature < 1`` samples from a sharper policy with the same argmax;
``loss.anchor_coef > 0`` adds to the actor's loss that weight times the KL divergence from the
starting policy (``init``, frozen, sampled at the same temperature) to the trained one, averaged
over the robots of a minibatch (:func:`anchor_kl`; AlphaStar's KL to its supervised policy), so
that PPO moves the cloned policy only where its advantages point.

Outputs in ``out``: ``config.yaml``, ``checkpoint.pt`` (resumable: re-run with the same ``out``),
``best.pt`` and ``model.pt`` (actor model files that ``scripts/evaluate.py checkpoint=...``
reads), with ``snapshots=true`` the actor at every evaluation as ``steps/step_NNNNNN.pt``
(NNNNNN: the iteration; ``scripts/select_average.py`` and ``scripts/average_models.py`` read
them), ``log/`` (TorchRL CSV or TensorBoard logger), ``curve.json`` (per iteration: losses,
sampled episode rewards, evaluation reward, collection/update/wall seconds) and
``summary.json``.
"""

from __future__ import annotations

import json
import logging
import math
import time
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
import torch

from agents import configuration
from agents.cli import write_text_atomic
from agents.evaluation import evaluate
from agents.models.gnn import AggregationGNN, GNNConfig
from agents.models.policy import GNNPolicy, load_model, make_actor, make_state_actor, save_model
from agents.models.value import AGGREGATES, EgoValue, StateValue
from agents.training.runs import LOGGERS, check_same_run, make_logger
from marl_cover.config import require
from marl_cover.env import CoverageEnv

logger = logging.getLogger(__name__)

GROUP = "robot"
ALGORITHMS = ("mappo", "ippo")
GRAPH_IN = ("nodes", "edge_index", "edge_attr", "edge_mask", "node_mask")


@dataclass
class CollectorConfig:
    """Data collection.

    Attributes:
        n_iters: Training iterations (one batch each).
        frames_per_batch: Env steps per batch (each holds ``num_robots`` observations).
        num_envs: Episodes stepped together per worker.
        workers: Collector processes (1: in the training process).
    """

    n_iters: int = 250
    frames_per_batch: int = 1000
    num_envs: int = 20
    workers: int = 1


REWARDS = ("team", "own")
ADVANTAGES = ("gae", "counterfactual")
CRITIC_INPUTS = ("state", "privileged")


@dataclass
class LossConfig:
    """``ClipPPOLoss`` and GAE settings (``reward``: ``"team"`` or ``"own"``; ``anchor_coef``:
    weight of the KL divergence from the ``init`` policy, 0: off; ``advantage``: ``"gae"`` or
    ``"counterfactual"``, simulated per-robot advantages; ``all_actions``: with
    ``"counterfactual"``, the clipped objective is taken in expectation over every move of a
    robot instead of at the sampled one, :func:`all_action_objective`; see the module
    docstring)."""

    gamma: float = 0.99
    lmbda: float = 0.95
    clip_epsilon: float = 0.2
    entropy_coef: float = 0.01
    critic_coef: float = 0.5
    normalize_advantage: bool = True
    reward_scale: float = 0.1
    reward: str = "team"
    anchor_coef: float = 0.0
    advantage: str = "gae"
    all_actions: bool = False


@dataclass
class OptimConfig:
    """Optimiser settings.

    Attributes:
        lr: Adam learning rate of the actor (and of the critic without ``critic_lr``).
        critic_lr: Learning rate of the critic (``None``: ``lr``).
        lr_anneal: Decay the learning rate linearly to 0 over ``n_iters``.
        epochs: Passes over each batch.
        minibatch_size: Env steps per minibatch.
        max_grad_norm: Gradient clipping.
        critic_warmup_iters: First iterations that train the critic only.
    """

    lr: float = 3e-4
    critic_lr: float | None = None
    lr_anneal: bool = False
    epochs: int = 4
    minibatch_size: int = 250
    max_grad_norm: float = 0.5
    critic_warmup_iters: int = 0


@dataclass
class ModelConfig:
    """Actor and critic networks (``temperature``: the sampling policy's logits are divided by
    it during training; below 1 the policy PPO improves is closer to the argmax policy that is
    evaluated and deployed, whose actions it does not change; ``critic_time``: see the module
    docstring; ``critic_input``: ``"state"`` or ``"privileged"``, see the module docstring;
    ``grow_actor``: with ``init``, the init model grown to ``actor``, a block per hop
    or more width or hops, with the same logits at the start: :meth:`AggregationGNN.grown_to`)."""

    actor: GNNConfig = field(default_factory=lambda: GNNConfig(kind="linear", hops=19))
    critic: GNNConfig = field(default_factory=lambda: GNNConfig(kind="linear", hops=19))
    actor_input: str = "state"
    value_aggregate: str = "robot"
    temperature: float = 1.0
    critic_time: bool = False
    critic_input: str = "state"
    grow_actor: bool = False


@dataclass
class EvalConfig:
    """Evaluation of the argmax policy during training (seeds disjoint from the test seeds)."""

    every: int = 10
    episodes: int = 20
    seed: int = 10_000


@dataclass
class MAPPOConfig:
    """A MAPPO/IPPO run (see the module docstring)."""

    out: str = "outputs/mappo/run"
    env: dict[str, Any] = field(default_factory=lambda: {"map": "paper", "hops": 19})
    algorithm: str = "mappo"
    init: str | None = None
    collector: CollectorConfig = field(default_factory=CollectorConfig)
    loss: LossConfig = field(default_factory=LossConfig)
    optim: OptimConfig = field(default_factory=OptimConfig)
    model: ModelConfig = field(default_factory=ModelConfig)
    eval: EvalConfig = field(default_factory=EvalConfig)
    seed: int = 0
    device: str = "cpu"  # "cpu", "cuda", "cuda:1", or "auto"
    threads: int = 1
    logger: str | None = "csv"
    progress: bool = True
    # keep the actor of every evaluation as out/steps/step_NNNNNN.pt (NNNNNN: the iteration), so
    # that a longer evaluation can choose among them, or average them, afterwards
    snapshots: bool = False

    def __post_init__(self) -> None:
        if self.algorithm not in ALGORITHMS:
            raise ValueError(f"algorithm must be one of {ALGORITHMS}, got {self.algorithm!r}")
        if self.model.actor_input not in ("state", "ego"):
            raise ValueError(
                f"model.actor_input must be state or ego, got {self.model.actor_input!r}"
            )
        if self.model.critic_input not in CRITIC_INPUTS:
            raise ValueError(
                f"model.critic_input must be one of {CRITIC_INPUTS}, got "
                f"{self.model.critic_input!r}"
            )
        if self.model.critic_input == "privileged" and self.algorithm != "mappo":
            raise ValueError(
                "model.critic_input=privileged needs algorithm=mappo (the ippo critic reads "
                "each robot's ego-graph)"
            )
        if self.loss.reward not in REWARDS:
            raise ValueError(f"loss.reward must be one of {REWARDS}, got {self.loss.reward!r}")
        if self.loss.advantage not in ADVANTAGES:
            raise ValueError(
                f"loss.advantage must be one of {ADVANTAGES}, got {self.loss.advantage!r}"
            )
        if self.loss.all_actions and self.loss.advantage != "counterfactual":
            raise ValueError("loss.all_actions needs loss.advantage=counterfactual")
        task = self.env.get("task", "coverage")
        if self.loss.advantage == "counterfactual" and task != "coverage":
            raise ValueError(
                f"loss.advantage=counterfactual needs the coverage task (greedy's play-outs), "
                f"not env.task={task!r}"
            )
        if self.model.value_aggregate not in AGGREGATES:
            raise ValueError(f"model.value_aggregate must be one of {AGGREGATES}")
        if self.logger is None:  # ``logger=none`` on the command line
            self.logger = "none"
        if self.logger not in LOGGERS:
            raise ValueError(f"logger must be one of {LOGGERS}, got {self.logger!r}")
        c = self.collector
        if min(c.n_iters, c.frames_per_batch, c.num_envs, c.workers) < 1:
            raise ValueError("collector.n_iters, frames_per_batch, num_envs, workers must be >= 1")
        if c.frames_per_batch % (c.num_envs * c.workers):
            raise ValueError(
                f"collector.frames_per_batch ({c.frames_per_batch}) must be a multiple of "
                f"num_envs * workers ({c.num_envs * c.workers})"
            )
        if self.optim.minibatch_size < 1 or self.optim.epochs < 1:
            raise ValueError("optim.minibatch_size and optim.epochs must be >= 1")
        if self.loss.anchor_coef < 0:
            raise ValueError(f"loss.anchor_coef must be >= 0, got {self.loss.anchor_coef}")
        if self.loss.anchor_coef > 0 and self.init is None:
            raise ValueError("loss.anchor_coef > 0 needs init= (the policy to stay near)")
        if self.model.grow_actor and self.init is None:
            raise ValueError("model.grow_actor needs init= (the model to grow to model.actor)")
        self._check_ranges()

    def _check_ranges(self) -> None:
        """Names a rate, coefficient or count outside its range."""
        loss, optim, ev = self.loss, self.optim, self.eval
        require(
            (0.0 < loss.gamma <= 1.0, f"loss.gamma must be in (0, 1], got {loss.gamma}"),
            (0.0 <= loss.lmbda <= 1.0, f"loss.lmbda must be in [0, 1], got {loss.lmbda}"),
            (loss.clip_epsilon > 0, f"loss.clip_epsilon must be > 0, got {loss.clip_epsilon}"),
            (
                loss.entropy_coef >= 0 and loss.critic_coef >= 0,
                "loss.entropy_coef and loss.critic_coef must be >= 0",
            ),
            (loss.reward_scale > 0, f"loss.reward_scale must be > 0, got {loss.reward_scale}"),
            (
                optim.lr > 0 and (optim.critic_lr is None or optim.critic_lr > 0),
                "optim.lr and optim.critic_lr must be > 0",
            ),
            (
                optim.max_grad_norm > 0,
                f"optim.max_grad_norm must be > 0, got {optim.max_grad_norm}",
            ),
            (optim.critic_warmup_iters >= 0, "optim.critic_warmup_iters must be >= 0"),
            (
                self.model.temperature > 0,
                f"model.temperature must be > 0, got {self.model.temperature}",
            ),
            (
                ev.every >= 1 and ev.episodes >= 1 and ev.seed >= 0,
                "eval.every and eval.episodes must be >= 1 and eval.seed >= 0",
            ),
            (self.seed >= 0 and self.threads >= 1, "seed must be >= 0 and threads >= 1"),
        )

    @property
    def needs_ego(self) -> bool:
        """Whether the environment must build the robots' ego-graphs."""
        return self.model.actor_input == "ego" or self.algorithm == "ippo"


# ---------------------------------------------------------------------------- modules
def resolve_device(name: str) -> torch.device:
    """``"auto"``: CUDA where available, else the CPU; any other name as ``torch.device``.

    Raises:
        ValueError: ``"cuda"`` asked for on a machine without a usable GPU.
    """
    if name == "auto":
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    device = torch.device(name)
    if device.type == "cuda" and not torch.cuda.is_available():
        raise ValueError(f"device={name} but torch sees no CUDA GPU here (use device=cpu or auto)")
    return device


def make_env(config: MAPPOConfig) -> Any:
    """The batched TorchRL environment of a run."""
    from agents.batched_env import BatchedCoverageEnv

    counterfactual_hops = None
    if config.loss.advantage == "counterfactual":
        counterfactual_hops = config.env.get("hops") or CoverageEnv(**config.env).config.hops
    return BatchedCoverageEnv(
        config.collector.num_envs,
        observe_robots=config.needs_ego,
        counterfactual_hops=counterfactual_hops,
        privileged_state=config.model.critic_input == "privileged",
        **config.env,
    )


def build_actor(gnn: AggregationGNN, config: MAPPOConfig, num_robots: int) -> Any:
    """The ``ProbabilisticActor`` on the batched environment's keys."""
    temperature = config.model.temperature
    if config.model.actor_input == "state":
        return make_state_actor(gnn, num_robots, temperature=temperature)
    return make_actor(
        gnn,
        observation_key=(GROUP, "observation"),
        action_key=(GROUP, "action"),
        mask_key=(GROUP, "action_mask"),
        temperature=temperature,
    )


def critic_config(config: MAPPOConfig) -> GNNConfig:
    """The critic network's shape (one node feature more with ``model.critic_time``)."""
    critic = config.model.critic
    if config.model.critic_time:
        critic = replace(critic, node_features=critic.node_features + 1)
    return critic


def build_critic(
    gnn: AggregationGNN, config: MAPPOConfig, num_robots: int, horizon: int | None = None
) -> Any:
    """The value module writing ``(robot, state_value)`` (``horizon``: the episode length, read
    with ``model.critic_time``)."""
    from tensordict.nn import TensorDictModule

    if config.model.critic_time and horizon is None:
        raise ValueError("model.critic_time needs the episode length (horizon)")
    horizon = horizon if config.model.critic_time else None
    root = config.model.critic_input  # the batched env's key: "state" or "privileged"
    time_keys = [(root, "steps_left")] if config.model.critic_time else []
    if config.algorithm == "ippo":
        return TensorDictModule(
            EgoValue(gnn, horizon),
            in_keys=[(GROUP, "observation", k) for k in GRAPH_IN] + time_keys,
            out_keys=[(GROUP, "state_value")],
        )
    return TensorDictModule(
        StateValue(gnn, num_robots, config.model.value_aggregate, horizon),
        in_keys=[(root, k) for k in GRAPH_IN] + time_keys,
        out_keys=[(GROUP, "state_value")],
    )


def build_loss(actor: Any, critic: Any, config: MAPPOConfig) -> Any:
    """``ClipPPOLoss`` with a GAE estimator on the group's keys."""
    from torchrl.objectives import ClipPPOLoss, ValueEstimators

    loss = ClipPPOLoss(
        actor_network=actor,
        critic_network=critic,
        clip_epsilon=config.loss.clip_epsilon,
        entropy_coeff=config.loss.entropy_coef,
        critic_coeff=config.loss.critic_coef,
        normalize_advantage=config.loss.normalize_advantage,
        normalize_advantage_exclude_dims=(-2,),  # per robot
    )
    loss.set_keys(
        reward=(GROUP, "reward"),
        action=(GROUP, "action"),
        sample_log_prob=(GROUP, "sample_log_prob"),
        value=(GROUP, "state_value"),
        done=(GROUP, "done"),
        terminated=(GROUP, "terminated"),
    )
    loss.make_value_estimator(  # the critic reads data-dependent sizes: no vmap
        ValueEstimators.GAE, gamma=config.loss.gamma, lmbda=config.loss.lmbda, deactivate_vmap=True
    )
    return loss


ANCHOR_KEY = (GROUP, "anchor_log_prob")


@torch.no_grad()
def anchor_log_probs(anchor: Any, batch: Any) -> torch.Tensor:
    """The frozen anchor's log-probabilities of every action ``(..., R, 5)`` (``-inf`` where
    masked), stored in a batch at :data:`ANCHOR_KEY` once, for every epoch that reads it."""
    return anchor.get_dist(batch).logits


def anchor_kl(actor: Any, batch: Any) -> torch.Tensor:
    """Mean over the batch and its robots of ``KL(anchor || actor)``, the divergence of the
    actor's masked categorical from the anchor's (:func:`anchor_log_probs`, at
    :data:`ANCHOR_KEY`) on the same observations."""
    reference = batch.get(ANCHOR_KEY)  # (..., R, 5)
    allowed = reference > -torch.inf
    current = actor.get_dist(batch).logits
    log_ratio = reference.masked_fill(~allowed, 0.0) - current.masked_fill(~allowed, 0.0)
    # the probabilities as the distribution computes them (softmax), to the bit
    return (reference.softmax(-1) * log_ratio).sum(-1).mean()


def prepare_batch(
    data: Any, reward_scale: float, reward: str = "team", end_is_terminal: bool = False
) -> Any:
    """Sets the reward each robot learns from (the team reward, or with ``reward="own"`` its
    own newly visited points of interest) times ``reward_scale``, and copies the episode ends
    onto every robot (GAE reads them beside the per-robot rewards), in place. With
    ``end_is_terminal`` every episode end (truncation at ``max_steps`` included) is terminal
    for GAE."""
    if reward not in REWARDS:
        raise ValueError(f"reward must be one of {REWARDS}, got {reward!r}")
    team = data.get(("next", GROUP, "reward"))  # (..., R, 1)
    if reward == "own":
        own = data.get(("next", GROUP, "info", "new_interest")).unsqueeze(-1)
        team = own.to(team.dtype)
    ends = {"done": "done", "terminated": "done" if end_is_terminal else "terminated"}
    for key, source in ends.items():
        data.set(("next", GROUP, key), data.get(("next", source)).unsqueeze(-2).expand(team.shape))
    data.set(("next", GROUP, "reward"), team * reward_scale)
    return data


COUNTERFACTUAL_KEY = ("next", GROUP, "info", "counterfactual")


OLD_LOGITS_KEY = (GROUP, "old_logits")
ALL_ADVANTAGES_KEY = (GROUP, "all_advantages")


@torch.no_grad()
def counterfactual_advantages(
    actor: Any, batch: Any, reward_scale: float, keep_all: bool = False
) -> torch.Tensor:
    """Each robot's advantage ``(..., R, 1)`` from the environment's simulated returns.

    ``Q[i, m]`` (:data:`COUNTERFACTUAL_KEY`, :func:`agents.greedy.counterfactual_returns`) is
    the team's return when robot ``i`` plays ``m`` with the others on the actions they took and
    greedy afterwards; the advantage of the move taken is ``Q[i, a_i] - sum_m pi(m) Q[i, m]``
    under the sampling policy (COMA's counterfactual baseline, with the values played out
    instead of learned), times ``reward_scale``. With ``keep_all`` the batch also stores, for
    :func:`all_action_objective`, the sampling policy's logits ``(..., R, 5)`` (``-inf`` where
    masked) at :data:`OLD_LOGITS_KEY` and every move's advantage ``(..., R, 5)`` at
    :data:`ALL_ADVANTAGES_KEY`.
    """
    q = batch.get(COUNTERFACTUAL_KEY)  # (..., R, 5)
    dist = actor.get_dist(batch)
    baseline = (dist.probs * q).sum(-1, keepdim=True)  # probabilities zero where masked
    every = (q - baseline) * reward_scale  # (..., R, 5)
    if keep_all:
        batch.set(OLD_LOGITS_KEY, dist.logits)
        batch.set(ALL_ADVANTAGES_KEY, every)
    return every.gather(-1, batch.get((GROUP, "action")).unsqueeze(-1))  # (..., R, 1)


def all_action_objective(actor: Any, batch: Any, clip_epsilon: float) -> torch.Tensor:
    """PPO's clipped surrogate in expectation over each robot's moves under the sampling
    policy, ``-sum_m pi_old(m) min(r_m A_m, clip(r_m, 1 - eps, 1 + eps) A_m)``, averaged over
    the robots of the batch (``r_m``: the probability ratio of move ``m``; ``A_m``: its
    advantage from :func:`counterfactual_advantages` with ``keep_all``, divided by their
    standard deviation over the allowed moves of the batch). Its expectation over sampled
    moves is the single-sample objective of ``ClipPPOLoss``; it reads every move's simulated
    value instead of one."""
    old = batch.get(OLD_LOGITS_KEY)  # (..., R, 5)
    allowed = old > -torch.inf
    advantage = batch.get(ALL_ADVANTAGES_KEY)
    scale = advantage[allowed].std().clamp_min(1e-8)
    advantage = torch.where(allowed, advantage / scale, torch.zeros_like(advantage))
    current = actor.get_dist(batch).logits
    log_ratio = (current.log_softmax(-1) - old.log_softmax(-1)).masked_fill(~allowed, 0.0)
    ratio = log_ratio.exp()
    clipped = ratio.clamp(1 - clip_epsilon, 1 + clip_epsilon)
    surrogate = torch.minimum(ratio * advantage, clipped * advantage)
    weights = old.softmax(-1)  # zero where masked
    return -(weights * surrogate).sum(-1).mean()


def episode_rewards(data: Any) -> list[float]:
    """Team rewards of the episodes that ended in a batch (the robots' credits at the end)."""
    done = data.get(("next", "done")).squeeze(-1)
    totals = data.get(("next", GROUP, "info", "total_interest")).sum(-1)
    return totals[done].float().tolist()


# ---------------------------------------------------------------------------- the loop
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
    defaults.pop("env")  # a free-form dict: the environment's own defaults fill it
    check_same_run(  # a key the saved config lacks (a run from before the key) reads as default
        out / "config.yaml",
        record,
        ignored=("progress", "out", "collector", "snapshots"),
        defaults=defaults,
    )
    write_text_atomic(out / "config.yaml", yaml.safe_dump(record, sort_keys=False))
    torch.manual_seed(config.seed)
    torch.set_num_threads(config.threads)

    eval_env = CoverageEnv(**config.env)
    num_robots = eval_env.config.num_robots
    actor_gnn = AggregationGNN(config.model.actor)
    metadata: dict[str, Any] = {"algorithm": config.algorithm, "seed": config.seed}
    if config.init is not None:
        actor_gnn, init_meta = load_model(config.init)
        metadata["init"] = {"path": config.init, **init_meta}
        if config.model.grow_actor:
            actor_gnn = _grown(actor_gnn, config)
    critic_gnn = AggregationGNN(critic_config(config))
    actor_gnn.to(device).train()
    critic_gnn.to(device).train()
    actor = build_actor(actor_gnn, config, num_robots)
    anchor = None
    if config.loss.anchor_coef > 0 and config.init is not None:  # (the config requires init)
        # the init file again: the same anchor when resuming
        anchor_gnn = load_model(config.init)[0].to(device).eval().requires_grad_(False)
        anchor = build_actor(anchor_gnn, config, num_robots)
    critic = build_critic(critic_gnn, config, num_robots, eval_env.config.max_steps)
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
    if iteration < c.n_iters:
        seed = config.seed + 100_003 * iteration
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
        data = prepare_batch(
            data.copy().to(device),
            config.loss.reward_scale,
            config.loss.reward,
            end_is_terminal=config.model.critic_time,
        )
        with torch.no_grad():
            loss_module.value_estimator(
                data,
                params=loss_module.critic_network_params,
                target_params=loss_module.target_critic_network_params,
            )
        buffer.empty()
        flat = data.reshape(-1)
        if config.loss.advantage == "counterfactual":  # replaces GAE's (the critic still trains)
            loss = config.loss
            advantage = counterfactual_advantages(actor, flat, loss.reward_scale, loss.all_actions)
            flat.set("advantage", advantage)
        if anchor is not None:
            flat.set(ANCHOR_KEY, anchor_log_probs(anchor, flat))
        buffer.extend(flat)
        if config.optim.lr_anneal:
            for group, base in zip(optimizer.param_groups, base_lrs, strict=True):
                group["lr"] = base * (1 - iteration / c.n_iters)
        actor_frozen = iteration < config.optim.critic_warmup_iters
        metrics = _update(loss_module, optimizer, buffer, config, actor_frozen, actor)
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
    state = torch.load(path, map_location=device, weights_only=False)
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
    actor: Any,
) -> dict[str, float]:
    """``epochs`` passes of PPO over the buffer; mean losses of the last pass. ``actor`` is
    read by the anchor's KL (``loss.anchor_coef > 0``: the buffer holds the anchor's
    log-probabilities) and by the objective of ``loss.all_actions``."""
    steps = max(1, len(buffer) // config.optim.minibatch_size)
    totals: dict[str, float] = {}
    for _ in range(config.optim.epochs):
        totals = {}
        for _ in range(steps):
            batch = buffer.sample()
            losses = loss_module(batch)
            if config.loss.all_actions:
                clip = config.loss.clip_epsilon
                losses["loss_objective"] = all_action_objective(actor, batch, clip)
            if actor_frozen:
                total = losses["loss_critic"]
            else:
                total = losses["loss_objective"] + losses["loss_critic"] + losses["loss_entropy"]
                if config.loss.anchor_coef > 0:
                    losses["kl_anchor"] = anchor_kl(actor, batch)
                    total = total + config.loss.anchor_coef * losses["kl_anchor"]
            optimizer.zero_grad()
            total.backward()
            torch.nn.utils.clip_grad_norm_(loss_module.parameters(), config.optim.max_grad_norm)
            optimizer.step()
            keys = ("loss_objective", "loss_critic", "loss_entropy", "entropy", "kl_approx")
            for key in (*keys, "kl_anchor"):
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
    if c.workers == 1:  # seeded before the collector's first reset, which it makes when built
        env = make_env(config)
        env.set_seed(seed)
        return Collector(env, actor, return_same_td=True, **kwargs)
    factories = [_EnvFactory(config)] * c.workers
    collector = MultiSyncCollector(factories, actor, **kwargs)
    collector.set_seed(seed)  # seeds the workers' environments, then resets them
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
