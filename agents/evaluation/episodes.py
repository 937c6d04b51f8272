"""Paired evaluation: any policy over a fixed list of episode seeds.

Every method evaluated with the same seeds sees the same maps, start waypoints and points of
interest, so comparisons between methods are paired.
"""

from __future__ import annotations

import math
import time
from collections import Counter
from collections.abc import Callable, Iterable, Sequence
from dataclasses import asdict, dataclass, field
from typing import Any, Protocol

import numpy as np

from marl_cover.env import CoverageEnv


class Policy(Protocol):
    """A policy: ``act(observations) -> actions`` keyed by agent name.

    A policy with ``act_state(state) -> (R,) actions`` is run on ``env.state()`` instead
    (centralized); one with ``reset(seed)`` is reset with the episode's seed.
    """

    def act(self, observations: dict[str, Any]) -> dict[str, int]:
        """One action per live agent from their observations."""


def decide(policy: Any, observations: dict[str, Any], env: CoverageEnv) -> dict[str, int]:
    """The policy's actions for the current step (centralized policies read ``env.state()``)."""
    if hasattr(policy, "act_env"):
        return policy.act_env(env)
    if hasattr(policy, "act_state"):
        actions = policy.act_state(env.state())
        return dict(zip(env.possible_agents, np.asarray(actions).tolist(), strict=True))
    return policy.act(observations)


@dataclass(frozen=True)
class EpisodeResult:
    """One evaluated episode."""

    seed: int
    reward: float
    coverage: float  # fraction of the points of interest visited, start waypoints included
    steps: int
    controller_seconds: float
    env_seconds: float
    policy_counts: dict[str, int] = field(default_factory=dict)  # e.g. an expert's fallbacks


@dataclass
class Summary:
    """Statistics of the episode rewards over the seeds."""

    episodes: int
    mean: float
    std: float
    sem: float
    ci95_low: float
    ci95_high: float
    mean_coverage: float
    controller_ms_per_step: float
    env_ms_per_step: float
    policy_counts: dict[str, int] = field(default_factory=dict)
    results: list[EpisodeResult] = field(default_factory=list, repr=False)

    def as_dict(self) -> dict[str, Any]:
        """Plain types, for JSON."""
        out = asdict(self)
        out["results"] = [asdict(r) for r in self.results]
        return out


def summarize(results: Sequence[EpisodeResult]) -> Summary:
    """Mean, standard deviation (ddof 1), SEM and a normal 95% interval of the rewards."""
    rewards = np.array([r.reward for r in results], dtype=np.float64)
    n = len(rewards)
    std = float(rewards.std(ddof=1)) if n > 1 else 0.0
    sem = std / math.sqrt(n) if n else 0.0
    mean = float(rewards.mean()) if n else math.nan
    steps = sum(r.steps for r in results) or 1
    return Summary(
        episodes=n,
        mean=mean,
        std=std,
        sem=sem,
        ci95_low=mean - 1.96 * sem,
        ci95_high=mean + 1.96 * sem,
        mean_coverage=float(np.mean([r.coverage for r in results])) if n else math.nan,
        controller_ms_per_step=1e3 * sum(r.controller_seconds for r in results) / steps,
        env_ms_per_step=1e3 * sum(r.env_seconds for r in results) / steps,
        policy_counts=dict(sum((Counter(r.policy_counts) for r in results), Counter())),
        results=list(results),
    )


def run_episode(env: CoverageEnv, policy: Any, seed: int) -> EpisodeResult:
    """Plays one episode with ``seed``; times the controller and the environment apart."""
    if hasattr(policy, "reset"):
        policy.reset(seed)
    start = time.perf_counter()
    observations, _ = env.reset(seed=seed)
    env_seconds = time.perf_counter() - start
    controller_seconds, total, steps = 0.0, 0.0, 0
    while env.agents:
        start = time.perf_counter()
        actions = decide(policy, observations, env)
        middle = time.perf_counter()
        observations, rewards, *_ = env.step(actions)
        env_seconds += time.perf_counter() - middle
        controller_seconds += middle - start
        total += next(iter(rewards.values()))
        steps += 1
    snap = env.snapshot()
    num_interest = int(snap.interest.sum())
    covered = int((snap.interest & snap.visited).sum())
    return EpisodeResult(
        seed=seed,
        reward=total,
        coverage=covered / num_interest if num_interest else 1.0,
        steps=steps,
        controller_seconds=controller_seconds,
        env_seconds=env_seconds,
        policy_counts=dict(getattr(policy, "counts", {})),
    )


def evaluate(
    env: CoverageEnv,
    policy: Any,
    seeds: Iterable[int],
    progress: Callable[[Iterable[int]], Iterable[int]] | None = None,
) -> Summary:
    """Runs ``policy`` on one episode per seed and summarizes.

    Args:
        env: The environment (its configuration fixes the task).
        policy: See :class:`Policy`.
        seeds: Episode seeds; the same list gives paired comparisons.
        progress: Optional wrapper such as ``tqdm`` around the seed iterator.
    """
    seeds = list(seeds)
    iterator = progress(seeds) if progress else seeds
    return summarize([run_episode(env, policy, seed) for seed in iterator])
