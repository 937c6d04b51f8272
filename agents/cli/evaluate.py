"""Evaluate a policy over fixed episode seeds (paired across methods); writes JSON and CSV.

Policies: ``greedy`` (each robot on its ego-graph), ``greedy_central`` (the same actions from
``state()``), ``expert`` (open-loop routing), ``expert_rh`` (receding horizon over ``env.hops``),
``expert_local`` (each robot plans alone over what its ego-graph holds), ``gnn`` (a shipped model
or a model file, ``model=``; argmax actions unless ``gnn.deterministic=false``), ``gnn_rollout``
(the one-step rollout of that GNN: an omniscient planner) and ``gnn_local_rollout`` (the
decentralized rollout: each robot plays its moves within ``gnn.margin`` of its best logit out on
its own ego-graph). A GNN runs with the receptive field it was trained with: ``env.hops``
follows the model's unless it is set. In exploration the experts plan on the true map
(``expert.information=full``, the imitation teacher), on what the team has discovered
(``known``, the fair expert) or on the floor plan with the discovered points (``expected``).

Episodes run in shards of ``shard_size`` seeds, where ``backend`` says: ``serial`` (here),
``process`` (``workers`` local processes) or ``ray`` (Ray tasks on a local instance or a
cluster, ``ray.address=auto``). Each episode is seeded by its own seed, so every backend writes
the same rows (the timing columns aside); a Ray task whose worker dies is retried.

Examples::

    marl-cover evaluate policy=greedy env.map=paper episodes=100 seed=0
    marl-cover evaluate policy=greedy episodes=200 backend=ray workers=2
    marl-cover evaluate policy=gnn env.map=paper                    # the shipped default
    marl-cover evaluate policy=gnn model=gnn_linear env.map=paper
    marl-cover evaluate policy=expert_rh expert.time_limit=0.15 env.task=exploration \
        expert.information=known env.map=paper
"""

from __future__ import annotations

import csv
import io
import json
import sys
from collections.abc import Sequence
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any

from marl_cover import EnvSettings, parallel_env
from marl_cover.agents.cli.options import parse
from marl_cover.agents.distributed import WorkerOptions, run_tasks
from marl_cover.agents.evaluation.episodes import EpisodeResult, evaluate, summarize
from marl_cover.agents.io import progress_bar, write_text_atomic
from marl_cover.config import require

POLICIES = (
    "greedy",
    "greedy_central",
    "expert",
    "expert_rh",
    "expert_local",
    "gnn",
    "gnn_rollout",
    "gnn_local_rollout",
)
FALLBACKS = ("random", "stay")


@dataclass
class ExpertOptions:
    """The routing experts (``policy=expert``, ``expert_rh``, ``expert_local``)."""

    backend: str = "pyvrp"  # pyvrp or ortools
    time_limit: float = 0.9  # seconds per solve
    seed: int = 0  # solver seed
    warm_start: bool = True  # start each solve from the previous plan
    information: str = "full"  # exploration: full, known or expected
    clock: bool = True  # expert_rh, expert_local: false plans over env.hops steps to the end
    iterations: int | None = None  # solver iterations per solve instead of time_limit
    fallback_reach: int | None = None  # expert, expert_rh: the fallback's reach (None: anywhere)


@dataclass
class GNNOptions:
    """The GNN policies (``policy=gnn``, ``gnn_rollout``, ``gnn_local_rollout``)."""

    centralized: bool = False  # gnn: one pass over state() instead of each ego-graph
    deterministic: bool = True  # gnn: argmax; false samples at temperature
    temperature: float = 1.0  # gnn with deterministic=false: the sampling temperature
    spread: float | None = None  # gnn: break argmax near-ties within this away from teammates
    sequential: bool = True  # gnn_rollout: robot by robot (false: each against the GNN's moves)
    margin: float = 1.0  # gnn_local_rollout: moves within this of the best logit play out
    horizon: int | None = None  # gnn_local_rollout: steps of a play-out (None: to the end)
    greedy_after: int | None = None  # rollouts: greedy plays after this many GNN moves


@dataclass
class EvaluateConfig(WorkerOptions):
    """An evaluation: a policy, the seeds, the environment, and where episodes run."""

    policy: str = "greedy"  # one of POLICIES
    model: str | None = None  # gnn*: a shipped model name or a file (None: the task's default)
    episodes: int = 100  # episodes, one per seed
    seed: int = 0  # first seed
    out: str = "outputs/evaluate.json"  # JSON summary; the per-seed CSV goes beside it
    fallback: str = "random"  # greedy, expert_local: random or stay when nothing is in reach
    shard_size: int = 10  # episodes of one task
    env: EnvSettings = field(default_factory=EnvSettings)
    expert: ExpertOptions = field(default_factory=ExpertOptions)
    gnn: GNNOptions = field(default_factory=GNNOptions)

    def __post_init__(self) -> None:
        super().__post_init__()
        policy, gnn, expert = self.policy, self.gnn, self.expert
        rollout = policy in ("gnn_rollout", "gnn_local_rollout")
        default = GNNOptions()
        planning = ("margin", "horizon")
        require(
            (policy in POLICIES, f"unknown policy {policy!r}; policies: {list(POLICIES)}"),
            (self.episodes >= 1 and self.seed >= 0, "episodes must be >= 1 and seed >= 0"),
            (self.shard_size >= 1, f"shard_size must be >= 1, got {self.shard_size}"),
            (self.fallback in FALLBACKS, f"fallback must be one of {FALLBACKS}"),
            (
                expert.clock or policy in ("expert_rh", "expert_local"),
                "expert.clock=false applies to policy=expert_rh and expert_local only",
            ),
            (
                expert.fallback_reach is None or policy in ("expert", "expert_rh"),
                "expert.fallback_reach applies to policy=expert and expert_rh only",
            ),
            (
                expert.information == "full" or policy != "expert_local",
                "expert.information does not apply to policy=expert_local (it plans on what "
                "each robot's ego-graph holds)",
            ),
            (
                gnn.temperature == 1.0 or (not gnn.deterministic and gnn.temperature > 0),
                f"gnn.temperature={gnn.temperature}: a sampling temperature (> 0) that needs "
                "gnn.deterministic=false",
            ),
            (
                gnn.spread is None
                or (policy == "gnn" and not gnn.centralized and gnn.deterministic)
                and gnn.spread >= 0,
                f"gnn.spread={gnn.spread}: a margin >= 0 for policy=gnn on the robots' "
                "ego-graphs (not with gnn.centralized or gnn.deterministic=false)",
            ),
            (
                not rollout or (gnn.deterministic and not gnn.centralized),
                f"gnn.deterministic=false and gnn.centralized do not apply to policy={policy} "
                "(it plays out the GNN's argmax)",
            ),
            (
                policy == "gnn_local_rollout"
                or all(getattr(gnn, name) == getattr(default, name) for name in planning),
                "gnn.margin and gnn.horizon apply to policy=gnn_local_rollout only",
            ),
            (
                gnn.greedy_after is None or rollout,
                "gnn.greedy_after applies to policy=gnn_rollout or gnn_local_rollout",
            ),
            (
                policy != "gnn_rollout" or gnn.greedy_after is None or gnn.greedy_after >= 1,
                f"policy=gnn_rollout needs gnn.greedy_after >= 1 (or null), got {gnn.greedy_after}",
            ),
            (
                policy != "gnn_local_rollout"
                or (
                    gnn.margin >= 0
                    and (gnn.horizon is None or gnn.horizon >= 1)
                    and (gnn.greedy_after is None or gnn.greedy_after >= 0)
                ),
                f"policy=gnn_local_rollout needs gnn.margin >= 0, gnn.horizon >= 1 (or null) "
                f"and gnn.greedy_after >= 0 (or null), got gnn.margin={gnn.margin} "
                f"gnn.horizon={gnn.horizon} gnn.greedy_after={gnn.greedy_after}",
            ),
            (
                self.model is None or policy.startswith("gnn"),
                f"model= applies to the gnn policies, not policy={policy}",
            ),
        )


def load_gnn(config: EvaluateConfig) -> tuple[Any, dict[str, Any], EvaluateConfig]:
    """The GNN to evaluate and its metadata; ``env.hops`` becomes the model's unless it was
    set to something else than the default.

    Raises:
        SystemExit: no such model (naming the shipped names and the path looked at).
    """
    import torch

    from marl_cover.agents.models.checkpoints import load_model
    from marl_cover.agents.models.shipped import default_model, model_path

    torch.set_num_threads(1)  # controller times are quoted for one thread
    name = config.model or default_model(config.env.task)
    try:
        path = model_path(name)
        model, metadata = load_model(path)
    except (FileNotFoundError, ValueError) as error:
        raise SystemExit(str(error)) from None
    hops = model.config.hops
    if config.env.hops == EnvSettings().hops:
        config = replace(config, env=replace(config.env, hops=hops))
    elif config.env.hops < hops:
        print(
            f"note: ego-graphs of {config.env.hops} hops are smaller than the model's "
            f"receptive field ({hops})",
            file=sys.stderr,
        )
    return model, {"model": str(name), "path": str(path), **metadata}, config


def make_policy(config: EvaluateConfig, model: Any = None) -> Any:
    """The policy ``config`` names (the GNN, the planners and the experts import lazily)."""
    policy, gnn, expert, hops = config.policy, config.gnn, config.expert, config.env.hops
    if policy == "gnn":
        from marl_cover.agents.models.policy import GNNPolicy

        return GNNPolicy(
            model,
            centralized=gnn.centralized,
            deterministic=gnn.deterministic,
            temperature=gnn.temperature,
            spread_margin=gnn.spread,
        )
    if policy == "gnn_rollout":
        from marl_cover.agents.planners.rollout import GNNArgmax, RolloutPolicy

        return RolloutPolicy(
            GNNArgmax(model), sequential=gnn.sequential, greedy_after=gnn.greedy_after
        )
    if policy == "gnn_local_rollout":
        from marl_cover.agents.planners.local_rollout import LocalRolloutPolicy

        return LocalRolloutPolicy(
            model, margin=gnn.margin, horizon=gnn.horizon, greedy_after=gnn.greedy_after
        )
    if policy in ("greedy", "greedy_central"):
        from marl_cover.agents.baselines.greedy import CentralizedGreedyPolicy, GreedyPolicy

        greedy = GreedyPolicy if policy == "greedy" else CentralizedGreedyPolicy
        return greedy(hops, fallback=config.fallback)
    from marl_cover.agents.experts import LocalRoutingExpert, RoutingExpert

    common: dict[str, Any] = {
        "backend": expert.backend,
        "time_limit": expert.time_limit,
        "seed": expert.seed,
        "max_iterations": expert.iterations,
        "clock": expert.clock,
    }
    if policy == "expert_local":
        return LocalRoutingExpert(hops, fallback=config.fallback, **common)
    receding = policy == "expert_rh"
    return RoutingExpert(
        mode="receding" if receding else "open_loop",
        horizon=hops if receding else None,
        warm_start=expert.warm_start,
        information=expert.information,
        fallback_reach=expert.fallback_reach,
        **common,
    )


def evaluate_shard(job: tuple[EvaluateConfig, list[int]]) -> list[EpisodeResult]:
    """One task: the episodes of some seeds, with the environment and policy built here."""
    config, seeds = job
    model = load_gnn(config)[0] if config.policy.startswith("gnn") else None
    env = parallel_env(**config.env.as_kwargs())
    return evaluate(env, make_policy(config, model), seeds).results


def evaluate_seeds(config: EvaluateConfig, seeds: Sequence[int]) -> list[EpisodeResult]:
    """The episodes of ``seeds``, in shards of ``config.shard_size`` where ``config`` says,
    ordered by seed; progress is shown as shards finish."""
    size = config.shard_size
    shards = [list(seeds[i : i + size]) for i in range(0, len(seeds), size)]
    bar = progress_bar(config.policy, unit="shard")
    finished = run_tasks(evaluate_shard, [(config, shard) for shard in shards], config)
    results = [
        r for _, part in (bar(finished, total=len(shards)) if bar else finished) for r in part
    ]
    return sorted(results, key=lambda r: r.seed)


def run(config: EvaluateConfig) -> dict[str, Any]:
    """Plays the episodes, writes ``out`` (JSON) and its CSV, prints the summary line."""
    model_info = None
    if config.policy.startswith("gnn"):
        _, model_info, config = load_gnn(config)
    try:
        env = parallel_env(**config.env.as_kwargs())  # checks the settings before any task
    except (FileNotFoundError, ValueError) as error:  # e.g. a grid file that is not there
        raise SystemExit(str(error)) from None
    seeds = range(config.seed, config.seed + config.episodes)
    summary = summarize(evaluate_seeds(config, seeds))
    record = {
        "config": asdict(config),
        "gnn": model_info,
        "summary": summary.as_dict(),
    }
    out = Path(config.out)
    write_text_atomic(out, json.dumps(record, indent=2))
    write_text_atomic(out.with_suffix(".csv"), results_csv(summary.results))
    print(
        f"{config.policy} on {env.config.map}, {summary.episodes} episodes "
        f"(seeds {seeds.start}..{seeds.stop - 1}): reward {summary.mean:.2f} +- "
        f"{summary.sem:.2f} (SEM), std {summary.std:.2f}, 95% CI [{summary.ci95_low:.2f}, "
        f"{summary.ci95_high:.2f}], coverage {100 * summary.mean_coverage:.1f}%, controller "
        f"{summary.controller_ms_per_step:.2f} ms/step, env {summary.env_ms_per_step:.2f} "
        f"ms/step, counts {summary.policy_counts}"
    )
    print(f"wrote {out} and {out.with_suffix('.csv')}")
    return record


def results_csv(results: Sequence[EpisodeResult]) -> str:
    """The per-seed CSV of an evaluation: one row per episode, in seed order."""
    rows = [asdict(r) for r in results]
    table = io.StringIO()
    writer = csv.DictWriter(table, fieldnames=list(rows[0]))
    writer.writeheader()
    writer.writerows(rows)
    return table.getvalue()


def main(argv: Sequence[str] | None = None, prog: str = "marl-cover evaluate") -> None:
    """``marl-cover evaluate``: see the module docstring."""
    args = sys.argv[1:] if argv is None else argv
    run(parse(EvaluateConfig, args, prog=prog, description=__doc__ or ""))
