"""Run independent tasks serially, in local processes or as Ray tasks, results as they finish.

A task is a module-level function applied to one picklable argument (a shard of episode
seeds, a dataset shard, a grid cell); it must seed everything it draws from its argument, never
from the worker it lands on, so every backend gives the same results. With Ray, a task whose
worker dies or that raises is retried up to ``ray.max_retries`` times; its result is taken once,
when it first completes, so nothing is lost or counted twice.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field
from multiprocessing import get_context
from typing import Any, TypeVar

from marl_cover.config import require

T = TypeVar("T")
R = TypeVar("R")

#: Where tasks run.
BACKENDS = ("serial", "process", "ray")


@dataclass
class RayOptions:
    """Ray settings (``backend=ray``)."""

    address: str = (
        ""  # "": start a local Ray instance; "auto": join the running cluster; or host:port
    )
    max_retries: int = 3  # reruns of a task whose worker died or that raised

    def __post_init__(self) -> None:
        require((self.max_retries >= 0, f"ray.max_retries must be >= 0, got {self.max_retries}"))


@dataclass
class WorkerOptions:
    """Where a job's tasks run: the fields every long job shares.

    Attributes:
        backend: ``serial`` (this process), ``process`` (``workers`` local processes; one
            worker runs here) or ``ray`` (Ray tasks, at most ``workers`` at a time, on a local
            instance or a cluster: ``ray.address``).
        workers: Tasks that run at once.
        ray: Ray settings.
    """

    backend: str = "serial"
    workers: int = 1
    ray: RayOptions = field(default_factory=RayOptions)

    def __post_init__(self) -> None:
        if isinstance(self.ray, dict):
            self.ray = RayOptions(**self.ray)
        require(
            (self.backend in BACKENDS, f"backend must be one of {BACKENDS}, got {self.backend!r}"),
            (self.workers >= 1, f"workers must be >= 1, got {self.workers}"),
        )


def run_tasks(
    task: Callable[[T], R], arguments: Sequence[T], options: WorkerOptions
) -> Iterator[tuple[int, R]]:
    """Runs ``task`` on every argument where ``options`` says; yields ``(index, result)`` as
    tasks finish (serially: in order).

    Raises:
        ModuleNotFoundError: ``backend=ray`` without ray installed (``pip install
            'marl-cover[ray]'``).
        Exception: a task's own error (with Ray, after its retries).
    """
    serial = options.backend == "serial" or (options.backend == "process" and options.workers == 1)
    if serial or not arguments:
        yield from ((i, task(argument)) for i, argument in enumerate(arguments))
    elif options.backend == "process":
        yield from _run_processes(task, arguments, options.workers)
    else:
        yield from _run_ray(task, arguments, options)


def _indexed(job: tuple[Callable[[Any], Any], int, Any]) -> tuple[int, Any]:
    task, index, argument = job
    return index, task(argument)


def _run_processes(
    task: Callable[[T], R], arguments: Sequence[T], workers: int
) -> Iterator[tuple[int, R]]:
    jobs = [(task, i, argument) for i, argument in enumerate(arguments)]
    with get_context("spawn").Pool(min(workers, len(jobs))) as pool:
        yield from pool.imap_unordered(_indexed, jobs)


def ray_init(options: RayOptions, num_cpus: int) -> bool:
    """Connects to Ray unless already connected: a local instance of ``num_cpus`` CPUs for an
    empty address, else the cluster at ``options.address`` (``"auto"``: the running one).

    Returns:
        Whether this call connected (the caller then disconnects, ``ray.shutdown()``, when
        done, so that no connection outlives the job that made it).
    """
    import ray

    if ray.is_initialized():
        return False
    if options.address:
        ray.init(address=options.address, log_to_driver=False)
    else:
        ray.init(address="local", num_cpus=num_cpus, include_dashboard=False, log_to_driver=False)
    return True


def _run_ray(
    task: Callable[[T], R], arguments: Sequence[T], options: WorkerOptions
) -> Iterator[tuple[int, R]]:
    import ray

    started = ray_init(options.ray, options.workers)
    remote = ray.remote(num_cpus=1, max_retries=options.ray.max_retries, retry_exceptions=True)(
        _indexed
    )
    pending: dict[Any, int] = {}
    queue = list(enumerate(arguments))
    try:
        while queue or pending:
            while queue and len(pending) < options.workers:  # at most `workers` at a time
                index, argument = queue.pop(0)
                pending[remote.remote((task, index, argument))] = index
            (done,), _ = ray.wait(list(pending), num_returns=1)
            del pending[done]
            yield ray.get(done)
    finally:
        if started:
            ray.shutdown()
