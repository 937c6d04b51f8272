"""The settings of a MAPPO / IPPO run (:class:`MAPPOConfig`), validated when built."""

from __future__ import annotations

from dataclasses import dataclass, field

from marl_cover.agents.distributed import WorkerOptions
from marl_cover.agents.models.gnn import GNNConfig
from marl_cover.agents.models.value import AGGREGATES
from marl_cover.agents.training.runs import LOGGERS
from marl_cover.config import EnvSettings, require

ALGORITHMS = ("mappo", "ippo")
REWARDS = ("team", "own")


@dataclass
class CollectorConfig(WorkerOptions):
    """Data collection (TorchRL collectors; the learner stays in the training process).

    Attributes:
        backend: ``process`` (``workers`` collector processes; one runs in the training
            process) or ``ray`` (``workers`` Ray actors, TorchRL's ``RayCollector``, on a
            local instance or a cluster: ``ray.address``); ``serial``: in the training process.
        workers: Collectors, each stepping its own batched environment.
        n_iters: Training iterations (one batch each).
        frames_per_batch: Env steps per batch, over all collectors (each step holds
            ``num_robots`` observations).
        num_envs: Episodes stepped together per collector.
    """

    backend: str = "process"
    n_iters: int = 250
    frames_per_batch: int = 1000
    num_envs: int = 20


@dataclass
class LossConfig:
    """``ClipPPOLoss`` and GAE settings (``reward``: ``"team"`` or ``"own"``, each robot's own
    points of interest)."""

    gamma: float = 0.99
    lmbda: float = 0.95
    clip_epsilon: float = 0.2
    entropy_coef: float = 0.01
    critic_coef: float = 0.5
    normalize_advantage: bool = True
    reward_scale: float = 0.1
    reward: str = "team"


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
    evaluated and deployed, whose actions it does not change; ``grow_actor``: with ``init``,
    the init model grown to ``actor``, a block per hop or more width or hops, with the same
    logits at the start: :meth:`AggregationGNN.grown_to`)."""

    actor: GNNConfig = field(default_factory=lambda: GNNConfig(kind="linear", hops=19))
    critic: GNNConfig = field(default_factory=lambda: GNNConfig(kind="linear", hops=19))
    actor_input: str = "state"
    value_aggregate: str = "robot"
    temperature: float = 1.0
    grow_actor: bool = False


@dataclass
class EvalConfig:
    """Evaluation of the argmax policy during training (seeds disjoint from the test seeds)."""

    every: int = 10
    episodes: int = 20
    seed: int = 10_000


@dataclass
class MAPPOConfig:
    """A MAPPO/IPPO run (see :mod:`marl_cover.agents.training.mappo`).

    Attributes:
        out: The run's folder (re-run with the same one to resume).
        env: The environment of the collection and the evaluations.
        algorithm: ``mappo`` (a critic on the whole state) or ``ippo`` (on each ego-graph).
        init: Start the actor from this model, a shipped name or a model file (a fine-tune).
        collector: Data collection.
        loss: The PPO loss and GAE.
        optim: The optimiser.
        model: The actor and critic networks.
        eval: The evaluations during training.
        seed: Seed of the initialisation and the collection.
        device: ``cpu``, ``cuda``, ``cuda:1`` or ``auto`` (CUDA where available).
        threads: Torch threads.
        logger: ``csv``, ``tensorboard`` or ``none``.
        progress: Show a progress bar.
        snapshots: Keep the actor of every evaluation as ``out/steps/step_NNNNNN.pt``
            (NNNNNN: the iteration), so that a longer evaluation can choose among them, or
            average them, afterwards.
    """

    out: str = "outputs/mappo/run"
    env: EnvSettings = field(default_factory=lambda: EnvSettings(map="paper"))
    algorithm: str = "mappo"
    init: str | None = None
    collector: CollectorConfig = field(default_factory=CollectorConfig)
    loss: LossConfig = field(default_factory=LossConfig)
    optim: OptimConfig = field(default_factory=OptimConfig)
    model: ModelConfig = field(default_factory=ModelConfig)
    eval: EvalConfig = field(default_factory=EvalConfig)
    seed: int = 0
    device: str = "cpu"
    threads: int = 1
    logger: str | None = "csv"
    progress: bool = True
    snapshots: bool = False

    def __post_init__(self) -> None:
        if isinstance(self.env, dict):  # a mapping of EnvSettings fields
            self.env = EnvSettings.from_dict(self.env)
        if self.algorithm not in ALGORITHMS:
            raise ValueError(f"algorithm must be one of {ALGORITHMS}, got {self.algorithm!r}")
        if self.model.actor_input not in ("state", "ego"):
            raise ValueError(
                f"model.actor_input must be state or ego, got {self.model.actor_input!r}"
            )
        if self.loss.reward not in REWARDS:
            raise ValueError(f"loss.reward must be one of {REWARDS}, got {self.loss.reward!r}")
        if self.model.value_aggregate not in AGGREGATES:
            raise ValueError(f"model.value_aggregate must be one of {AGGREGATES}")
        if self.logger is None:  # ``logger=none`` on the command line
            self.logger = "none"
        if self.logger not in LOGGERS:
            raise ValueError(f"logger must be one of {LOGGERS}, got {self.logger!r}")
        c = self.collector
        if isinstance(c, dict):
            c = self.collector = CollectorConfig(**c)
        if c.backend == "serial" and c.workers != 1:
            raise ValueError("collector.backend=serial collects in the training process: workers=1")
        if min(c.n_iters, c.frames_per_batch, c.num_envs, c.workers) < 1:
            raise ValueError("collector.n_iters, frames_per_batch, num_envs, workers must be >= 1")
        if c.frames_per_batch % (c.num_envs * c.workers):
            raise ValueError(
                f"collector.frames_per_batch ({c.frames_per_batch}) must be a multiple of "
                f"num_envs * workers ({c.num_envs * c.workers})"
            )
        if self.optim.minibatch_size < 1 or self.optim.epochs < 1:
            raise ValueError("optim.minibatch_size and optim.epochs must be >= 1")
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
