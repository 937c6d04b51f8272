"""GNN controller time per step, beside the paper's; prints a table and writes JSON.

Times the policy only (observations are recorded first): from the observation arrays to the
actions, on one CPU thread (or ``device=cuda``), for the linear and non-linear models at each
K. Rows: 4 robots on windows of the paper's map, each robot on its own ego-graph
(decentralized) and all robots in one pass over ``state()`` (centralized); and 100 robots on
the 5659-waypoint map, centralized, at K = 19. Weights are random: the time does not depend on
them. ``models`` adds rows for shipped models or model files (their own shape: width, a block
per hop) at their K.

``repeats=R`` times every case R times, the passes interleaved across the three modes, and
reports the lowest median: these machines slow down by up to 1.5x when another process wakes,
and the lowest pass is the code's speed with the least of that. Each row also records the
largest logit difference between its modes on the recorded states (``max_logit_gap``): the
modes time the same controller, and the command exits with an error when they disagree.

Example::

    marl-cover bench-gnn hops=[19] steps=20 models=[gnn]
"""

from __future__ import annotations

import json
import platform
import sys
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import torch

from marl_cover import parallel_env
from marl_cover.agents.cli.options import parse
from marl_cover.agents.io import write_text_atomic
from marl_cover.agents.models.checkpoints import load_model
from marl_cover.agents.models.gnn import KINDS, AggregationGNN, GNNConfig
from marl_cover.agents.models.logits import centralized_logits, decentralized_logits
from marl_cover.agents.models.shipped import model_path
from marl_cover.config import require

#: The paper's controller time per step (ms per 50-step episode / 50; GNNs on a GTX 1080).
PAPER_MS = {
    ("nonlinear", 9): 176 / 50,
    ("nonlinear", 19): 277 / 50,
    ("linear", 9): 133 / 50,
    ("linear", 19): 171 / 50,
}
GRAPH_KEYS = ("nodes", "edge_index", "edge_attr", "edge_mask")
#: Largest logit difference between the timed modes that float rounding explains.
GAP_TOLERANCE = 1e-3


def record_states(env_kwargs: dict, steps: int) -> list[tuple[dict, dict]]:
    """(stacked ego-observations, state) pairs along random-action episodes."""
    env = parallel_env(**env_kwargs)
    rng = np.random.default_rng(0)
    pairs: list[tuple[dict[str, np.ndarray], dict[str, np.ndarray]]] = []
    seed = 0
    env.reset(seed=seed)
    while len(pairs) < steps:
        if not env.agents:
            seed += 1
            env.reset(seed=seed)
        pairs.append((env.observe_batch(), env.state()))
        masks = env.state()["action_mask"]
        actions = [int(rng.choice(np.flatnonzero(m))) for m in masks]
        env.step(dict(zip(env.possible_agents, actions, strict=True)))
    return pairs


def mode_logits(
    model: AggregationGNN, observations: dict, state: dict, mode: str, device: str
) -> np.ndarray:
    """Action logits on the host from numpy observations, as a controller computes them.

    ``mode``: ``"central"`` (one pass over the state; ``(R, 5)``), ``"decentral"`` (every
    robot's ego-graph in one batch; ``(R, 5)``) or ``"one_robot"`` (robot 0's ego-graph
    alone, what each robot computes on its own computer; ``(1, 5)``).
    """
    if mode == "central":
        tensors = {k: torch.from_numpy(v).to(device) for k, v in state.items()}
        logits = centralized_logits(model, tensors)
    else:
        robots = slice(0, 1) if mode == "one_robot" else slice(None)
        tensors = {k: torch.from_numpy(observations[k][robots]).to(device) for k in GRAPH_KEYS}
        logits = decentralized_logits(model, tensors)
    return logits.cpu().numpy()


def time_policy(model: AggregationGNN, pairs: list, mode: str, device: str) -> float:
    """Median milliseconds from numpy observations to actions on the host, over one pass on
    the recorded states (:func:`mode_logits` and the argmax)."""
    times = []
    with torch.inference_mode():
        for observations, state in pairs[:5]:  # warm-up
            mode_logits(model, observations, state, mode, device).argmax(-1)
        for observations, state in pairs:
            start = time.perf_counter()
            mode_logits(model, observations, state, mode, device).argmax(-1)
            times.append(time.perf_counter() - start)
    return 1000.0 * float(np.median(times))


def logit_gap(model: AggregationGNN, pairs: list, modes: tuple[str, ...], device: str) -> float:
    """Largest difference between the timed modes' logits of the same robot on the recorded
    states (every mode computes the same controller: a gap above float rounding is a bug);
    infinite where the modes mask different actions."""
    gap = 0.0
    with torch.inference_mode():
        for observations, state in pairs:
            reference = mode_logits(model, observations, state, modes[-1], device)
            for mode in modes[:-1]:
                logits = mode_logits(model, observations, state, mode, device)
                other = reference[: len(logits)]
                finite = np.isfinite(logits)
                if not np.array_equal(finite, np.isfinite(other)):
                    return float("inf")
                if finite.any():
                    gap = max(gap, float(np.abs(logits[finite] - other[finite]).max()))
    return gap


def time_modes(
    model: AggregationGNN, pairs: list, modes: tuple[str, ...], device: str, repeats: int
) -> dict[str, float]:
    """:func:`time_policy` of each mode, ``repeats`` passes interleaved across the modes; the
    lowest pass median of each (a burst of work from another process slows a pass, never
    speeds one up)."""
    passes: dict[str, list[float]] = {mode: [] for mode in modes}
    for _ in range(repeats):
        for mode in modes:
            passes[mode].append(time_policy(model, pairs, mode, device))
    return {mode: min(times) for mode, times in passes.items()}


@dataclass
class BenchGNNConfig:
    """The cases and how they are timed."""

    hops: list[int] = field(default_factory=lambda: list(range(3, 20, 2)))  # receptive fields
    steps: int = 100  # recorded states per case
    device: str = "cpu"  # cpu or cuda
    threads: int = 1  # torch threads
    repeats: int = 1  # passes per case; the lowest median is kept
    models: list[str] = field(default_factory=list)  # shipped names or model files, extra rows
    out: str = "outputs/bench_gnn.json"  # the JSON of every row

    def __post_init__(self) -> None:
        require(
            (all(k >= 1 for k in self.hops), f"hops must be >= 1, got {self.hops}"),
            (min(self.steps, self.threads, self.repeats) >= 1, "counts must be >= 1"),
        )


def main(argv: Sequence[str] | None = None, prog: str = "marl-cover bench-gnn") -> None:
    """``marl-cover bench-gnn``: see the module docstring."""
    argv = sys.argv[1:] if argv is None else argv
    args = parse(BenchGNNConfig, argv, prog=prog, description=__doc__ or "")
    torch.set_num_threads(args.threads)
    rows: list[dict[str, Any]] = []
    print(
        f"controller ms/step (median; the lowest of {args.repeats} passes), {args.device}, "
        f"{args.threads} thread(s)"
    )
    print(
        f"{'model':<10} {'K':>3} {'robots':>6} {'map':<12} {'one robot':>10} {'decentral':>10} "
        f"{'central':>9} {'paper':>7} {'logit gap':>10}"
    )
    files = [(name, load_model(model_path(name))[0]) for name in args.models]
    cases = [(hops, 4, "paper") for hops in args.hops] + [(19, 100, "paper_large")]
    for hops, robots, map_name in cases:
        pairs = record_states(
            {"map": map_name, "hops": hops, "num_robots": robots},
            args.steps if robots == 4 else max(10, args.steps // 5),
        )
        torch.manual_seed(0)
        models = [(kind, AggregationGNN(GNNConfig(kind=kind, hops=hops))) for kind in KINDS]
        models += [(name, model) for name, model in files if model.config.hops == hops]
        for kind, model in models:
            model = model.to(args.device).eval()
            small = robots <= 4
            modes = ("one_robot", "decentral", "central") if small else ("central",)
            timed = time_modes(model, pairs, modes, args.device, args.repeats)
            one = timed.get("one_robot", float("nan"))
            decentral = timed.get("decentral", float("nan"))
            central = timed["central"]
            gap = logit_gap(model, pairs, modes, args.device) if len(modes) > 1 else 0.0
            paper = PAPER_MS.get((kind, hops)) if robots == 4 else None
            rows.append(
                {
                    "kind": kind,
                    "hidden": model.config.hidden,
                    "per_hop": model.config.per_hop,
                    "hops": hops,
                    "robots": robots,
                    "map": map_name,
                    "one_robot_ms": one,
                    "decentralized_ms": decentral,
                    "centralized_ms": central,
                    "paper_ms": paper,
                    "max_logit_gap": gap,
                }
            )
            print(
                f"{kind:<10} {hops:>3} {robots:>6} {map_name:<12} {one:>10.2f} {decentral:>10.2f} "
                f"{central:>9.2f} {paper if paper else float('nan'):>7.2f} {gap:>10.1e}"
            )
    record = {
        "device": args.device,
        "threads": args.threads,
        "repeats": args.repeats,
        "torch": torch.__version__,
        "machine": platform.processor() or platform.machine(),
        "rows": rows,
    }
    write_text_atomic(args.out, json.dumps(record, indent=2))
    print(f"wrote {args.out}")
    if any(row["max_logit_gap"] > GAP_TOLERANCE for row in rows):
        raise SystemExit(f"the modes' logits differ by more than {GAP_TOLERANCE} (logit gap)")
