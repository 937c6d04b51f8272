"""Collect expert episodes into a compact, resumable dataset of shards.

Shard ``k`` holds the episodes with seeds ``seed + k * shard_size ...``. Each shard is written
atomically and recorded in ``out/manifest.json`` with its SHA-256, beside the dataset's
settings (a resume with other settings is refused). Running the same command again after an
interrupt keeps the shards that match the manifest and collects the rest; a shard that is
corrupted, truncated or unrecorded is named and re-collected (``bad_shards=recollect``) or
stops the run (``bad_shards=raise``). Episodes are seeded by their own seeds, so a re-collected
shard is the same file. Load the episodes with
``marl_cover.agents.training.datasets.load_dataset(out)``.

Example (the dataset behind the shipped models, about 10 minutes on two cores)::

    marl-cover collect episodes=2000 workers=2 out=data/coverage_expert
"""

from __future__ import annotations

import hashlib
import sys
import time
from collections.abc import Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from marl_cover import EnvSettings, parallel_env
from marl_cover.agents.cli.options import parse
from marl_cover.agents.distributed import WorkerOptions, run_tasks
from marl_cover.agents.io import progress_bar, write_bytes_atomic
from marl_cover.agents.training.datasets import (
    SHARD_PATTERN,
    ShardManifest,
    record_episode,
    shard_bytes,
)
from marl_cover.config import require

#: Settings that may change between the legs of one dataset (a dataset may be moved).
RESUMABLE = ("out", "backend", "workers", "ray", "max_shards", "bad_shards")


@dataclass
class CollectExpert:
    """The recording expert (``marl_cover.agents.experts.RoutingExpert``)."""

    mode: str = "open_loop"  # open_loop or receding (over env.hops steps)
    backend: str = "pyvrp"  # pyvrp or ortools
    time_limit: float = 0.5  # seconds per plan, when iterations is 0
    iterations: int = 1500  # solver iterations per plan (deterministic); 0: use time_limit

    def __post_init__(self) -> None:
        from marl_cover.agents.experts.expert import MODES

        require(
            (self.mode in MODES, f"expert.mode must be one of {MODES}, got {self.mode!r}"),
            (
                self.backend in ("pyvrp", "ortools"),
                f"expert.backend must be pyvrp or ortools, got {self.backend!r}",
            ),
            (self.time_limit > 0, f"expert.time_limit must be > 0, got {self.time_limit}"),
            (self.iterations >= 0, f"expert.iterations must be >= 0, got {self.iterations}"),
        )


@dataclass
class CollectConfig(WorkerOptions):
    """A dataset of expert episodes, and where its shards are collected."""

    backend: str = "process"  # serial, process or ray (one task per shard)
    workers: int = 2  # shards collected at once
    episodes: int = 2000  # episodes, one per seed
    seed: int = 0  # first seed
    shard_size: int = 50  # episodes per shard file
    out: str = "data/coverage_expert"  # the dataset's folder
    max_shards: int = -1  # stop after writing this many new shards (-1: all)
    bad_shards: str = "recollect"  # a bad shard on resume: recollect or raise
    env: EnvSettings = field(default_factory=lambda: EnvSettings(map="paper"))
    expert: CollectExpert = field(default_factory=CollectExpert)

    def __post_init__(self) -> None:
        super().__post_init__()
        require(
            (
                min(self.episodes, self.shard_size) >= 1,
                "episodes and shard_size must be >= 1",
            ),
            (self.seed >= 0, f"seed must be >= 0, got {self.seed}"),
            (
                self.bad_shards in ("recollect", "raise"),
                f"bad_shards must be recollect or raise, got {self.bad_shards!r}",
            ),
        )


def collect_shard(job: tuple[int, list[int], dict[str, Any]]) -> tuple[int, bytes, float]:
    """Records one shard; returns (shard, the shard file's bytes, seconds). The driver writes
    it, so workers on other machines need no shared disk."""
    from marl_cover.agents.experts import RoutingExpert

    shard, seeds, config = job
    start = time.perf_counter()
    env = parallel_env(**config["env"])
    expert = config["expert"]
    policy = RoutingExpert(
        backend=expert["backend"],
        mode=expert["mode"],
        horizon=env.config.hops if expert["mode"] == "receding" else None,
        time_limit=expert["time_limit"],
        max_iterations=expert["iterations"] or None,
    )
    episodes = [record_episode(env, policy, seed) for seed in seeds]
    return shard, shard_bytes(episodes), time.perf_counter() - start


def open_manifest(out: Path, settings: dict[str, Any]) -> ShardManifest:
    """The dataset's manifest, new or resumed; a new one records ``settings``.

    Raises:
        SystemExit: ``out`` holds a dataset of other settings, naming the keys that differ.
    """
    manifest = ShardManifest(out)
    if manifest.config is None:
        manifest.config = settings
        manifest.save()
        return manifest
    previous = manifest.config
    keys = (set(previous) | set(settings)) - set(RESUMABLE)
    differ = sorted(k for k in keys if previous.get(k) != settings.get(k))
    if differ:
        raise SystemExit(
            f"{out} holds a dataset made with other settings ({differ} differ, "
            f"{manifest.path}); use another out= or the same settings to resume"
        )
    return manifest


def shards_to_collect(manifest: ShardManifest, num_shards: int, bad_shards: str) -> list[int]:
    """The shards that are not on disk whole: missing ones, and bad ones (named on stdout).

    Raises:
        SystemExit: a bad shard with ``bad_shards="raise"``, naming it and what is wrong.
    """
    todo = []
    for shard in range(num_shards):
        name = SHARD_PATTERN.format(shard)
        problem = manifest.problem(name)
        if problem is None:
            continue
        if problem != "missing":
            if bad_shards == "raise":
                raise SystemExit(
                    f"{manifest.folder / name}: {problem}; run with bad_shards=recollect "
                    "to collect it again"
                )
            print(f"{manifest.folder / name}: {problem}; collecting it again", flush=True)
            manifest.shards.pop(name, None)
        todo.append(shard)
    return todo


def run(config: CollectConfig) -> None:
    """Collects the missing shards of the dataset."""
    out = Path(config.out)
    out.mkdir(parents=True, exist_ok=True)
    settings = asdict(config)
    manifest = open_manifest(out, settings)
    for stale in out.glob(".tmp_*"):  # left by a collection killed mid-write
        stale.unlink()
    num_shards = -(-config.episodes // config.shard_size)
    jobs = []
    for shard in shards_to_collect(manifest, num_shards, config.bad_shards):
        first = config.seed + shard * config.shard_size
        last = min(config.seed + config.episodes, first + config.shard_size)
        jobs.append((shard, list(range(first, last)), settings))
    if config.max_shards >= 0:
        jobs = jobs[: config.max_shards]
    done = num_shards - len(jobs) if config.max_shards < 0 else None
    print(f"{num_shards} shards, {len(jobs)} to collect, {config.workers} workers -> {out}")
    start = time.perf_counter()
    seeds = {shard: seeds for shard, seeds, _ in jobs}
    finished = run_tasks(collect_shard, jobs, config)
    bar = progress_bar("collect", unit="shard")
    for _, (shard, data, seconds) in bar(finished, total=len(jobs)) if bar else finished:
        write_bytes_atomic(out / SHARD_PATTERN.format(shard), data)
        digest = hashlib.sha256(data).hexdigest()
        manifest.add(SHARD_PATTERN.format(shard), digest, seeds[shard])
        if bar is None:
            print(f"shard {shard}: {len(seeds[shard])} episodes in {seconds:.1f} s", flush=True)
    size = sum(p.stat().st_size for p in out.glob("shard_*.npz"))
    print(
        f"collected {len(jobs)} shards in {time.perf_counter() - start:.1f} s; dataset "
        f"{size / 2**20:.2f} MB on disk" + (f" ({done} shards were already there)" if done else "")
    )


def main(argv: Sequence[str] | None = None, prog: str = "marl-cover collect") -> None:
    """``marl-cover collect``: see the module docstring."""
    args = sys.argv[1:] if argv is None else argv
    run(parse(CollectConfig, args, prog=prog, description=__doc__ or ""))
