"""The settings of a behaviour-cloning run (:class:`BCConfig`) and its DAgger rounds
(:class:`DaggerConfig`), validated when built."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from marl_cover.agents.experts.expert import INFORMATION
from marl_cover.agents.models.gnn import GNNConfig
from marl_cover.agents.training.runs import LOGGERS
from marl_cover.config import EnvSettings, require


@dataclass
class DaggerConfig:
    """DAgger rounds after the initial behaviour cloning (``rounds = 0``: off).

    Attributes:
        rounds: Rounds of roll-out, labelling and retraining.
        episodes: Episodes rolled out per round.
        beta: Probability of executing the expert's action at a step, first round.
        beta_decay: ``beta`` is multiplied by this after each round.
        steps: Training steps after each round.
        iterations: Expert solver iterations per label (PyVRP; deterministic labels).
        seed: First roll-out episode seed (rounds use consecutive blocks).
        fraction: Share of every batch drawn from the DAgger states once there are any (the
            rest from the expert dataset). ``None``: the DAgger states join the dataset and
            are drawn as often as any transition (a few percent of a batch).
        expert_mode: The labelling expert: ``"open_loop"`` (the dataset's expert, re-planned
            from each state the learner leads to) or ``"receding"`` (plans over
            ``expert_horizon`` steps at every state).
        expert_horizon: Planning horizon of the receding expert, in steps.
        expert_clock: ``False``: the receding expert plans over ``expert_horizon`` steps even
            near the end of the episode, so its labels depend only on what the (clock-blind)
            network sees.
        expert_information: What the routing expert plans on in exploration
            (:class:`~marl_cover.agents.experts.RoutingExpert`'s ``information``): ``"full"``
            (the true map and every point, the paper's teacher), ``"known"`` or ``"expected"``
            (the true map, the discovered points, and each undiscovered waypoint worth the
            share of points of interest among the discovered ones).
        env: Overrides of the BC ``env`` for the roll-outs (e.g. ``{"map": "paper_full",
            "num_robots": 10, "max_steps": 131}``: states of a larger map and team than the
            dataset's). With any, the DAgger states are collated apart from the dataset's
            (their own graphs, team size and padding) and ``fraction`` is required.
        reuse: Folders of DAgger shards labelled by earlier runs (their ``out/dagger``), which
            join this run's DAgger states before its first round: states another learner
            visited, labelled by the same kind of expert, are more data near the learner's
            distribution. They must come from the same roll-out env as this run's.
    """

    rounds: int = 0
    episodes: int = 50
    beta: float = 0.5
    beta_decay: float = 0.5
    steps: int = 3000
    iterations: int = 500
    seed: int = 1_000_000
    fraction: float | None = None
    expert_mode: str = "open_loop"
    expert_horizon: int | None = None
    expert_clock: bool = True
    expert_information: str = "full"
    env: dict[str, Any] = field(default_factory=dict)
    reuse: list[str] = field(default_factory=list)

    def __post_init__(self) -> None:
        if self.fraction is not None and not 0.0 < self.fraction < 1.0:
            raise ValueError(f"dagger.fraction must be in (0, 1) or null, got {self.fraction}")
        if self.expert_mode not in ("open_loop", "receding"):
            raise ValueError(
                f"dagger.expert_mode must be 'open_loop' or 'receding', got {self.expert_mode!r}"
            )
        if self.expert_mode == "receding" and (
            self.expert_horizon is None or self.expert_horizon < 1
        ):
            raise ValueError("dagger.expert_mode=receding needs dagger.expert_horizon >= 1")
        if not self.expert_clock and self.expert_mode != "receding":
            raise ValueError("dagger.expert_clock=false needs dagger.expert_mode=receding")
        if self.expert_information not in INFORMATION:
            raise ValueError(
                f"dagger.expert_information must be one of {INFORMATION}, "
                f"got {self.expert_information!r}"
            )
        if self.env and self.fraction is None:
            raise ValueError("dagger.env needs dagger.fraction (the share of its states)")
        require(
            (self.rounds >= 0 and self.steps >= 0, "dagger.rounds and dagger.steps must be >= 0"),
            (self.episodes >= 1, f"dagger.episodes must be >= 1, got {self.episodes}"),
            (0.0 <= self.beta <= 1.0, f"dagger.beta must be in [0, 1], got {self.beta}"),
            (
                0.0 <= self.beta_decay <= 1.0,
                f"dagger.beta_decay must be in [0, 1], got {self.beta_decay}",
            ),
            (self.iterations >= 1, f"dagger.iterations must be >= 1, got {self.iterations}"),
            (self.seed >= 0, f"dagger.seed must be >= 0, got {self.seed}"),
        )


@dataclass
class BCConfig:
    """Behaviour cloning settings (see :mod:`marl_cover.agents.training.bc` for the recipe).

    Attributes:
        dataset: Folder of the expert dataset (``marl-cover collect``).
        bad_shards: A dataset shard that fails its checksum or cannot be read: ``"raise"``
            (stop, naming it) or ``"skip"`` (train without it, with a warning naming it).
        out: The run's folder (re-run with the same one to resume).
        model: The network trained.
        init: Start from this model, a shipped name or a model file: its config must equal
            ``model``, or be ``model`` with one shared block where ``model.per_hop`` is set,
            fewer ``hops`` and/or a smaller ``hidden`` (the model then grows from it with the
            same logits: ``AggregationGNN.grown_to``).
        env: The environment of the dataset, the selection and the DAgger roll-outs.
        batch_size: Episode states per batch (every robot of a state is labelled).
        lr: Adam's learning rate at the start of each phase.
        lr_decay: The learning rate is multiplied by this every ``lr_decay_every`` batches.
        lr_decay_every: Batches between learning-rate decays.
        steps: Behaviour-cloning batches before the DAgger rounds.
        entropy_coef: Weight of the policy's entropy subtracted from the loss.
        max_episodes: Use at most this many dataset episodes (``None``: all).
        holdout_seeds: ``[first, stop)``: dataset seeds held out (the evaluation seeds).
        val_fraction: Share of the episodes kept for validation.
        val_every: Batches between validations, selections and checkpoints.
        select_episodes: Episodes of the selection reward (``best.pt``).
        select_seed: First seed of the selection episodes.
        select_env: Overrides of ``env`` for the selection episodes (another map or team).
        snapshots: Keep the model of every validation as ``out/steps/step_NNNNNN.pt``, so that
            a longer evaluation can choose among them (or average them) afterwards.
        seed: Seed of the initialisation, the split and the sampling order.
        threads: Torch threads.
        logger: ``csv``, ``tensorboard`` or ``none``.
        progress: Show a progress bar.
        ties: Train on the set of actions as good as each label: the dataset's from its
            trajectories, the DAgger states' as their expert recorded them.
        dagger: The DAgger rounds after behaviour cloning.
    """

    dataset: str = "data/coverage_expert"
    bad_shards: str = "raise"
    out: str = "outputs/bc/run"
    model: GNNConfig = field(default_factory=GNNConfig)
    init: str | None = None
    env: EnvSettings = field(default_factory=lambda: EnvSettings(map="paper"))
    batch_size: int = 32
    lr: float = 1e-3
    lr_decay: float = 0.95
    lr_decay_every: int = 200
    steps: int = 20_000
    entropy_coef: float = 0.0
    max_episodes: int | None = None
    holdout_seeds: list[int] = field(default_factory=lambda: [0, 100])
    val_fraction: float = 0.05
    val_every: int = 1000
    select_episodes: int = 20
    select_seed: int = 10_000
    select_env: dict[str, Any] = field(default_factory=dict)
    snapshots: bool = True
    seed: int = 0
    threads: int = 1
    logger: str = "csv"
    progress: bool = True
    ties: bool = False
    dagger: DaggerConfig = field(default_factory=DaggerConfig)

    def __post_init__(self) -> None:
        if isinstance(self.env, dict):  # a mapping of EnvSettings fields
            self.env = EnvSettings.from_dict(self.env)
        if self.batch_size < 1 or self.steps < 0 or self.val_every < 1:
            raise ValueError("batch_size and val_every must be >= 1 and steps >= 0")
        if not 0.0 < self.val_fraction < 1.0:
            raise ValueError(f"val_fraction must be in (0, 1), got {self.val_fraction}")
        if self.logger not in LOGGERS:
            raise ValueError(f"logger must be one of {LOGGERS}, got {self.logger!r}")
        if len(self.holdout_seeds) != 2:
            raise ValueError("holdout_seeds is [first, stop)")
        require(
            (self.lr > 0, f"lr must be > 0, got {self.lr}"),
            (0.0 < self.lr_decay <= 1.0, f"lr_decay must be in (0, 1], got {self.lr_decay}"),
            (self.lr_decay_every >= 1, f"lr_decay_every must be >= 1, got {self.lr_decay_every}"),
            (
                self.max_episodes is None or self.max_episodes >= 1,
                f"max_episodes must be >= 1 or null, got {self.max_episodes}",
            ),
            (
                self.select_episodes >= 1,
                f"select_episodes must be >= 1, got {self.select_episodes}",
            ),
            (self.seed >= 0 and self.select_seed >= 0, "seed and select_seed must be >= 0"),
            (self.threads >= 1, f"threads must be >= 1, got {self.threads}"),
            (
                self.bad_shards in ("raise", "skip"),
                f"bad_shards must be raise or skip, got {self.bad_shards!r}",
            ),
        )

    @property
    def total_steps(self) -> int:
        """Batches of the whole run: the cloning steps plus every DAgger round's."""
        return self.steps + self.dagger.rounds * self.dagger.steps
