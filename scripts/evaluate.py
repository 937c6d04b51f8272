"""Evaluate a policy over fixed episode seeds (paired across methods); writes JSON and CSV.

    python scripts/evaluate.py task=coverage policy=greedy hops=19 episodes=100 seed=0 \\
        map=paper out=results.json
    python scripts/evaluate.py policy=expert expert.backend=ortools expert.time_limit=1.0
    python scripts/evaluate.py policy=expert_rh hops=19 expert.time_limit=0.15
    python scripts/evaluate.py policy=expert_rh hops=19 expert.clock=false expert.iterations=200
    python scripts/evaluate.py task=exploration policy=expert_rh expert.information=known map=paper
    python scripts/evaluate.py policy=expert_rh hops=19 expert.fallback_reach=19  # stays beyond
    python scripts/evaluate.py policy=expert_local hops=19 expert.clock=false expert.iterations=200
    python scripts/evaluate.py policy=gnn map=paper                 # the shipped model
    python scripts/evaluate.py policy=gnn checkpoint=outputs/bc/nonlinear_k19/best.pt \
        map=paper_large num_robots=100 gnn.centralized=true
    python scripts/evaluate.py policy=gnn checkpoint=A.pt,B.pt,C.pt map=paper  # an ensemble

Tasks: ``coverage`` or ``exploration`` (the map is discovered with a range sensor,
``sensor_range=22``); ``task`` also picks the shipped model. In exploration the experts are
omniscient by default (``expert.information=full``, the imitation teacher), fair
(``expert.information=known``: only what the team has discovered), or planning on the floor
plan (``expert.information=expected``: the true map, the discovered points, and each
undiscovered waypoint worth the share of points of interest among the discovered ones).
Policies: ``greedy`` (each robot on its ego-graph), ``greedy_central`` (same actions, from
``state()``), ``expert`` (open-loop routing), ``expert_rh`` (receding horizon over ``hops``;
``expert.clock=false``: over ``hops`` steps even near the end, blind to the clock),
``expert_local`` (each robot plans alone over what its ``hops``-hop ego-graph holds,
``agents.experts.LocalRoutingExpert``; ``fallback`` with nothing in view),
``gnn`` (the shipped model of the task, or ``checkpoint=PATH``; each robot on its own
ego-graph, or ``gnn.centralized=true`` for one pass over ``state()``; argmax actions unless
``gnn.deterministic=false``, which samples at ``gnn.temperature`` (default 1);
``gnn.spread=0.5`` breaks the argmax's near-ties, moves within 0.5 of the best logit, toward
the one that leads farthest from the nearest teammate in the robot's ego-graph
(``agents.spread``); comma-separated files play as one ensemble,
``agents.models.policy.EnsemblePolicy``). A GNN runs with the receptive field it was trained
with: ``hops`` defaults to the model's (the largest of an ensemble's). ``gnn_rollout``: the
one-step rollout policy of that GNN (``agents.rollout``: each robot's move is the one whose
exact play-out, every robot then on the GNN's argmax, returns most; robot by robot, which is
never worse than the GNN, or ``gnn.sequential=false`` each against the GNN's moves), an
omniscient planner, about 22 s an episode on the paper's windows (``gnn.greedy_after=1``: the
play-outs are the joint move, then greedy; about 0.5 s an episode). ``gnn_local_rollout``: the
decentralized one (``agents.local_rollout``): each robot plays its moves within
``gnn.margin`` (default 1.0) of its best logit out on its own ego-graph, its teammates in
view and itself then on the GNN's argmax, for ``gnn.horizon`` steps (default: to the end);
in exploration it plays on the discovered waypoints in view, and
``gnn.frontier_as_interest=true`` also scores the frontier there; about 3 s an episode on the
paper's windows; ``gnn.greedy_after=N``: greedy plays the play-outs' moves after the GNN's
first N (faster); ``gnn.world=true_map``: an oracle bound, not a controller, that plays them
out on the true map within each robot's ``hops`` (in exploration the undiscovered part too;
``agents.local_rollout.TrueMapRolloutPolicy``); ``gnn.world=true_layout``: the same true
waypoints and edges with only the points of interest the team has discovered;
``gnn.world=optimistic_layout``: those waypoints and edges with every undiscovered waypoint
counted as a point of interest (an optimistic prior on a perfectly known layout).
Maps: ``city`` (default), ``paper`` (windows of the paper's map), ``paper_full``,
``paper_large``, or a grid file. Any other ``key=value`` is a field of ``CoverageConfig``
(``num_robots=10``, ``max_steps=49``, ...); an unknown key is an error.
"""

from __future__ import annotations

import csv
import io
import json
import sys
from dataclasses import asdict, dataclass, fields
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from agents.cli import parse_value, progress_bar, write_text_atomic  # noqa: E402
from agents.evaluation import evaluate  # noqa: E402
from marl_cover import CoverageConfig, parallel_env  # noqa: E402
from marl_cover.config import TASKS, check_field_types  # noqa: E402

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
#: What each true-map world puts on the undiscovered waypoints (``TrueMapRolloutPolicy``'s hidden).
_HIDDEN = {"true_map": "true", "true_layout": "none", "optimistic_layout": "all"}
#: Worlds of ``gnn_local_rollout``'s play-outs: the robot's view, or oracles on the true map.
WORLDS = ("view", *_HIDDEN)


@dataclass
class ExpertOptions:
    backend: str = "pyvrp"
    time_limit: float = 0.9
    seed: int = 0
    warm_start: bool = True
    information: str = "full"
    clock: bool = True  # expert_rh: false plans over `hops` steps even when fewer are left
    iterations: int | None = None  # PyVRP iterations per solve instead of time_limit
    fallback_reach: int | None = None  # expert, expert_rh: the fallback's reach (None: anywhere)


@dataclass
class GNNOptions:
    centralized: bool = False
    deterministic: bool = True
    temperature: float = 1.0  # with deterministic=false: sample at this temperature
    sequential: bool = True  # gnn_rollout: robot by robot (False: each against the GNN's moves)
    spread: float | None = None  # break the argmax's near-ties away from teammates (agents.spread)
    margin: float = 1.0  # gnn_local_rollout: moves within this of the best logit are played out
    horizon: int | None = None  # gnn_local_rollout: steps of a play-out (None: to the end)
    frontier_as_interest: bool = False  # gnn_local_rollout, exploration: the frontier scores
    greedy_after: int | None = None  # gnn_(local_)rollout: greedy after this many GNN moves
    world: str = "view"  # gnn_local_rollout: "view" (the ego-graph) or an oracle of WORLDS


@dataclass
class EvaluateOptions:
    task: str = "coverage"
    policy: str = "greedy"
    episodes: int = 100
    seed: int = 0
    out: str = "outputs/evaluate.json"
    fallback: str = "random"  # greedy's (and expert_local's) choice when nothing is in reach
    checkpoint: str | None = None  # policy=gnn: a model file (default: the shipped model)
    # or comma-separated model files: an ensemble


def parse_overrides(
    argv: list[str],
) -> tuple[EvaluateOptions, ExpertOptions, GNNOptions, dict[str, Any]]:
    """Splits ``key=value`` arguments into script, expert, GNN and environment options.

    Raises:
        SystemExit: a malformed argument or an unknown key, naming it.
    """
    options, expert, gnn = EvaluateOptions(), ExpertOptions(), GNNOptions()
    env: dict[str, Any] = {}
    sections: dict[str, Any] = {"expert": expert, "gnn": gnn}
    env_keys = {f.name for f in fields(CoverageConfig)} - {"graph", "render_mode"}
    for arg in argv:
        if "=" not in arg:
            raise SystemExit(f"arguments are key=value overrides, got {arg!r}")
        key, text = arg.split("=", 1)
        value = parse_value(text)
        section, _, name = key.partition(".")
        if name and section in sections:
            options_of_section = sections[section]
            names = {f.name for f in fields(options_of_section)}
            if name not in names:
                raise SystemExit(
                    f"unknown key {key!r}; {section} keys: "
                    f"{sorted(f'{section}.{n}' for n in names)}"
                )
            setattr(options_of_section, name, value)
        elif key in {f.name for f in fields(EvaluateOptions)}:
            setattr(options, key, value if key not in ("out", "checkpoint") else text)
        elif key in env_keys:
            env[key] = value if key != "map" else text
        else:
            raise SystemExit(
                f"unknown key {key!r}; script keys "
                f"{sorted(f.name for f in fields(EvaluateOptions))}, environment "
                f"keys {sorted(env_keys)}, expert.* and gnn.*"
            )
    for checked in (options, expert, gnn):
        try:
            check_field_types(checked)
        except TypeError as error:
            raise SystemExit(str(error)) from error
    if options.task not in TASKS:
        raise SystemExit(f"unknown task {options.task!r}; tasks: {list(TASKS)}")
    if options.episodes < 1 or options.seed < 0:
        raise SystemExit(
            f"episodes must be >= 1 and seed >= 0, got episodes={options.episodes} "
            f"seed={options.seed}"
        )
    env["task"] = options.task
    try:
        CoverageConfig(**env)  # names a bad environment value before anything runs
    except (TypeError, ValueError) as error:
        raise SystemExit(str(error)) from error
    if options.policy not in POLICIES:
        raise SystemExit(f"unknown policy {options.policy!r}; policies: {list(POLICIES)}")
    if not expert.clock and options.policy not in ("expert_rh", "expert_local"):
        raise SystemExit("expert.clock=false applies to policy=expert_rh and expert_local only")
    if expert.fallback_reach is not None and options.policy not in ("expert", "expert_rh"):
        raise SystemExit("expert.fallback_reach applies to policy=expert and expert_rh only")
    if gnn.temperature != 1.0 and (gnn.deterministic or not gnn.temperature > 0):
        raise SystemExit(
            f"gnn.temperature={gnn.temperature}: a sampling temperature (> 0) that needs "
            "gnn.deterministic=false"
        )
    if gnn.spread is not None and (
        options.policy != "gnn" or gnn.centralized or not gnn.deterministic or not gnn.spread >= 0
    ):
        raise SystemExit(
            f"gnn.spread={gnn.spread}: a margin >= 0 for policy=gnn on the robots' ego-graphs "
            "(not with gnn.centralized or gnn.deterministic=false)"
        )
    rollout = options.policy in ("gnn_rollout", "gnn_local_rollout")
    if rollout and "," in (options.checkpoint or ""):
        raise SystemExit(f"policy={options.policy} plays out one model, not an ensemble")
    if rollout and (not gnn.deterministic or gnn.centralized):
        raise SystemExit(
            f"gnn.deterministic=false and gnn.centralized do not apply to policy={options.policy} "
            "(it plays out the GNN's argmax)"
        )
    default = GNNOptions()
    planning = ("margin", "horizon", "frontier_as_interest", "world")
    if options.policy != "gnn_local_rollout" and any(
        getattr(gnn, name) != getattr(default, name) for name in planning
    ):
        raise SystemExit(
            "gnn.margin, gnn.horizon, gnn.frontier_as_interest and gnn.world apply to "
            "policy=gnn_local_rollout only"
        )
    if gnn.world not in WORLDS:
        raise SystemExit(f"gnn.world must be one of {list(WORLDS)}, got {gnn.world!r}")
    if gnn.world != "view" and gnn.frontier_as_interest:
        raise SystemExit(f"gnn.frontier_as_interest does not apply to gnn.world={gnn.world}")
    if gnn.greedy_after is not None and not rollout:
        raise SystemExit("gnn.greedy_after applies to policy=gnn_rollout or gnn_local_rollout")
    if options.policy == "gnn_rollout" and gnn.greedy_after is not None and gnn.greedy_after < 1:
        raise SystemExit(
            f"policy=gnn_rollout needs gnn.greedy_after >= 1 (or null), got {gnn.greedy_after}"
        )
    if options.policy == "gnn_local_rollout" and not (
        gnn.margin >= 0
        and (gnn.horizon is None or gnn.horizon >= 1)
        and (gnn.greedy_after is None or gnn.greedy_after >= 0)
    ):
        raise SystemExit(
            f"policy=gnn_local_rollout needs gnn.margin >= 0, gnn.horizon >= 1 (or null) and "
            f"gnn.greedy_after >= 0 (or null), got gnn.margin={gnn.margin} "
            f"gnn.horizon={gnn.horizon} gnn.greedy_after={gnn.greedy_after}"
        )
    if expert.information != "full" and options.policy == "expert_local":
        raise SystemExit(
            "expert.information does not apply to policy=expert_local (it plans on what each "
            "robot's ego-graph holds)"
        )
    return options, expert, gnn, env


def load_gnn(options: EvaluateOptions, env_overrides: dict[str, Any]) -> tuple[Any, dict]:
    """The GNN to evaluate (a list of them for an ensemble) and its metadata; sets ``hops`` to
    the model's (the largest) unless given."""
    import torch

    from agents.models.policy import load_model
    from agents.models.shipped import shipped_model_path

    torch.set_num_threads(1)  # controller times are quoted for one thread
    path = options.checkpoint or str(shipped_model_path(options.task))
    parts = path.split(",")
    try:
        loaded = [load_model(part) for part in parts]
    except (FileNotFoundError, ValueError) as error:
        raise SystemExit(str(error)) from error
    model: Any
    (model, metadata), hops = loaded[0], max(m.config.hops for m, _ in loaded)
    if len(parts) > 1:
        model, metadata = [m for m, _ in loaded], {"ensemble": parts}
    env_overrides.setdefault("hops", hops)
    if env_overrides["hops"] < hops:
        print(
            f"note: ego-graphs of {env_overrides['hops']} hops are smaller than the model's "
            f"receptive field ({hops})",
            file=sys.stderr,
        )
    return model, {"path": str(path), **metadata}


def make_policy(
    options: EvaluateOptions, expert: ExpertOptions, hops: int, gnn: GNNOptions, model: Any = None
) -> Any:
    if options.policy == "gnn":
        from agents.models.policy import EnsemblePolicy, GNNPolicy

        cls = EnsemblePolicy if isinstance(model, list) else GNNPolicy
        return cls(
            model,
            centralized=gnn.centralized,
            deterministic=gnn.deterministic,
            temperature=gnn.temperature,
            spread_margin=gnn.spread,
        )
    if options.policy == "gnn_rollout":
        from agents.rollout import GNNArgmax, RolloutPolicy

        return RolloutPolicy(
            GNNArgmax(model), sequential=gnn.sequential, greedy_after=gnn.greedy_after
        )
    if options.policy == "gnn_local_rollout":
        from agents.local_rollout import LocalRolloutPolicy, TrueMapRolloutPolicy

        if gnn.world != "view":
            return TrueMapRolloutPolicy(
                model,
                hidden=_HIDDEN[gnn.world],
                margin=gnn.margin,
                horizon=gnn.horizon,
                greedy_after=gnn.greedy_after,
            )
        return LocalRolloutPolicy(
            model,
            margin=gnn.margin,
            horizon=gnn.horizon,
            frontier_as_interest=gnn.frontier_as_interest,
            greedy_after=gnn.greedy_after,
        )
    if options.policy in ("greedy", "greedy_central"):
        from agents.greedy import CentralizedGreedyPolicy, GreedyPolicy

        greedy = GreedyPolicy if options.policy == "greedy" else CentralizedGreedyPolicy
        return greedy(hops, fallback=options.fallback)
    from agents.experts import LocalRoutingExpert, RoutingExpert

    common: dict[str, Any] = {
        "backend": expert.backend,
        "time_limit": expert.time_limit,
        "seed": expert.seed,
        "max_iterations": expert.iterations,
        "clock": expert.clock,
    }
    if options.policy == "expert_local":
        return LocalRoutingExpert(hops, fallback=options.fallback, **common)
    receding = options.policy == "expert_rh"
    return RoutingExpert(
        mode="receding" if receding else "open_loop",
        horizon=hops if receding else None,
        warm_start=expert.warm_start,
        information=expert.information,
        fallback_reach=expert.fallback_reach,
        **common,
    )


def main(argv: list[str]) -> None:
    options, expert, gnn, env_overrides = parse_overrides(argv)
    model, model_info = (
        load_gnn(options, env_overrides) if options.policy.startswith("gnn") else (None, None)
    )
    try:
        env = parallel_env(**env_overrides)
    except (FileNotFoundError, ValueError) as error:  # e.g. a grid file that is not there
        raise SystemExit(str(error)) from error
    policy = make_policy(options, expert, env.config.hops, gnn, model)
    seeds = range(options.seed, options.seed + options.episodes)
    summary = evaluate(env, policy, seeds, progress=progress_bar(options.policy))
    record = {
        "options": asdict(options),
        "expert": asdict(expert) if options.policy.startswith("expert") else None,
        "gnn": {**asdict(gnn), **model_info} if model_info is not None else None,
        "env": {k: v for k, v in asdict(env.config).items() if k != "graph"},
        "summary": summary.as_dict(),
    }
    out = Path(options.out)
    write_text_atomic(out, json.dumps(record, indent=2))
    rows = [asdict(r) for r in summary.results]
    table = io.StringIO()
    writer = csv.DictWriter(table, fieldnames=list(rows[0]))
    writer.writeheader()
    writer.writerows(rows)
    write_text_atomic(out.with_suffix(".csv"), table.getvalue())
    print(
        f"{options.policy} on {env.config.map}, {summary.episodes} episodes "
        f"(seeds {seeds.start}..{seeds.stop - 1}): reward {summary.mean:.2f} +- "
        f"{summary.sem:.2f} (SEM), std {summary.std:.2f}, 95% CI [{summary.ci95_low:.2f}, "
        f"{summary.ci95_high:.2f}], coverage {100 * summary.mean_coverage:.1f}%, controller "
        f"{summary.controller_ms_per_step:.2f} ms/step, env {summary.env_ms_per_step:.2f} "
        f"ms/step, counts {summary.policy_counts}"
    )
    print(f"wrote {out} and {out.with_suffix('.csv')}")


if __name__ == "__main__":
    main(sys.argv[1:])
