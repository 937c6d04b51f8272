"""Collect expert episodes into a compact, resumable dataset of shards.

    python scripts/collect_expert.py episodes=2000 workers=2 out=data/coverage_expert \\
        map=paper expert.backend=pyvrp expert.time_limit=0.5 shard_size=50

Shard ``k`` holds the episodes with seeds ``seed + k * shard_size ...``; shards already on disk
are skipped, so running the same command again after an interrupt finishes the dataset with no
episode lost or repeated. Each shard is written atomically. Load with
``agents.datasets.load_dataset(out)``.
"""

from __future__ import annotations

import json
import sys
import time
from collections.abc import Iterable
from dataclasses import asdict, dataclass, fields
from multiprocessing import get_context
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from agents.cli import parse_value  # noqa: E402
from agents.datasets import SHARD_PATTERN, record_episode, write_shard  # noqa: E402
from marl_cover import CoverageConfig, parallel_env  # noqa: E402
from marl_cover.config import check_field_types  # noqa: E402


@dataclass
class CollectOptions:
    episodes: int = 2000
    seed: int = 0
    shard_size: int = 50
    workers: int = 2
    out: str = "data/coverage_expert"
    mode: str = "open_loop"
    backend: str = "pyvrp"
    time_limit: float = 0.5
    iterations: int = 1500  # solver iterations per plan (deterministic); 0: use time_limit
    max_shards: int = -1  # stop after writing this many new shards (-1: all); for tests


def parse(argv: list[str]) -> tuple[CollectOptions, dict[str, Any]]:
    options, env = CollectOptions(), {}
    names = {f.name for f in fields(CollectOptions)}
    env_keys = {f.name for f in fields(CoverageConfig)} - {"graph", "render_mode"}
    for arg in argv:
        if "=" not in arg:
            raise SystemExit(f"arguments are key=value overrides, got {arg!r}")
        key, text = arg.split("=", 1)
        key = {
            "expert.backend": "backend",
            "expert.time_limit": "time_limit",
            "expert.mode": "mode",
            "expert.iterations": "iterations",
        }.get(key, key)
        if key in names:
            setattr(options, key, text if key in ("out", "mode", "backend") else parse_value(text))
        elif key in env_keys:
            env[key] = text if key == "map" else parse_value(text)
        else:
            raise SystemExit(f"unknown key {key!r}; keys: {sorted(names | env_keys)}")
    check(options, env)
    return options, env


def check(options: CollectOptions, env: dict[str, Any]) -> None:
    """Names a bad setting before anything is written.

    Raises:
        SystemExit: a value of the wrong type or out of range, or a bad environment key.
    """
    from agents.experts import MODES
    from agents.experts.backends import BACKENDS

    problems = []
    try:
        check_field_types(options)
        CoverageConfig(**env)
    except (TypeError, ValueError) as error:
        raise SystemExit(f"collect_expert: {error}") from error
    for name in ("episodes", "shard_size", "workers"):
        if getattr(options, name) < 1:
            problems.append(f"{name} must be >= 1, got {getattr(options, name)}")
    if options.seed < 0 or options.iterations < 0:
        problems.append(
            f"seed and iterations must be >= 0, got {options.seed}, {options.iterations}"
        )
    if not options.time_limit > 0:
        problems.append(f"expert.time_limit must be > 0 seconds, got {options.time_limit}")
    if options.mode not in MODES:
        problems.append(f"expert.mode must be one of {MODES}, got {options.mode!r}")
    if options.backend not in BACKENDS:
        problems.append(f"expert.backend must be one of {BACKENDS}, got {options.backend!r}")
    if problems:
        raise SystemExit("collect_expert: " + "; ".join(problems))


def collect_shard(job: tuple[int, list[int], dict, dict]) -> tuple[int, int, float]:
    """Records and writes one shard; returns (shard, episodes, seconds)."""
    from agents.experts import RoutingExpert

    shard, seeds, options, env_config = job
    start = time.perf_counter()
    env = parallel_env(**env_config)
    expert = RoutingExpert(
        backend=options["backend"],
        mode=options["mode"],
        horizon=env.config.hops if options["mode"] == "receding" else None,
        time_limit=options["time_limit"],
        max_iterations=options["iterations"] or None,
    )
    episodes = [record_episode(env, expert, seed) for seed in seeds]
    write_shard(Path(options["out"]) / SHARD_PATTERN.format(shard), episodes)
    return shard, len(episodes), time.perf_counter() - start


def main(argv: list[str]) -> None:
    options, env_config = parse(argv)
    out = Path(options.out)
    out.mkdir(parents=True, exist_ok=True)
    meta = {"options": asdict(options), "env": env_config}
    meta_path = out / "meta.json"
    if meta_path.exists():
        previous = json.loads(meta_path.read_text())
        same = {k: v for k, v in previous["options"].items() if k not in ("workers", "max_shards")}
        now = {k: v for k, v in meta["options"].items() if k not in ("workers", "max_shards")}
        if same != now or previous["env"] != env_config:
            raise SystemExit(
                f"{out} holds a dataset made with other settings ({meta_path}); "
                "use another out= or the same settings to resume"
            )
    else:
        meta_path.write_text(json.dumps(meta, indent=2))
    for stale in out.glob(".tmp_*"):  # left by a collection killed mid-write
        stale.unlink()
    num_shards = -(-options.episodes // options.shard_size)
    jobs = []
    for shard in range(num_shards):
        if (out / SHARD_PATTERN.format(shard)).exists():
            continue
        first = options.seed + shard * options.shard_size
        last = min(options.seed + options.episodes, first + options.shard_size)
        jobs.append((shard, list(range(first, last)), asdict(options), env_config))
    if options.max_shards >= 0:
        jobs = jobs[: options.max_shards]
    done = num_shards - len(jobs) if options.max_shards < 0 else None
    print(
        f"{num_shards} shards, {len(jobs)} to collect, {options.workers} workers -> {out}",
        flush=True,
    )
    try:
        from tqdm import tqdm
    except ImportError:
        tqdm = None
    bar = (
        tqdm(total=sum(len(j[1]) for j in jobs), unit="episode", file=sys.stderr) if tqdm else None
    )
    start = time.perf_counter()
    results: Iterable[tuple[int, int, float]]
    if options.workers <= 1:
        results = map(collect_shard, jobs)
    else:
        pool = get_context("spawn").Pool(options.workers)
        results = pool.imap_unordered(collect_shard, jobs)
    for shard, count, seconds in results:
        if bar:
            bar.update(count)
        else:
            print(f"shard {shard}: {count} episodes in {seconds:.1f} s", flush=True)
    if options.workers > 1:
        pool.close()
        pool.join()
    if bar:
        bar.close()
    size = sum(p.stat().st_size for p in out.glob("shard_*.npz"))
    print(
        f"collected {len(jobs)} shards in {time.perf_counter() - start:.1f} s; dataset "
        f"{size / 2**20:.2f} MB on disk" + (f" ({done} shards were already there)" if done else "")
    )


if __name__ == "__main__":
    main(sys.argv[1:])
