"""Where long jobs run: in this process, in local worker processes, or on a Ray cluster.

Every long job (evaluation, expert datasets, evaluation grids, MAPPO collection) takes the
same settings, :class:`WorkerOptions`: ``backend=serial|process|ray``, ``workers=N`` and
``ray.address``. Nothing imports ray unless a run asks for ``backend=ray``.
"""

from marl_cover.agents.distributed.executor import (
    BACKENDS,
    RayOptions,
    WorkerOptions,
    run_tasks,
)

__all__ = ["BACKENDS", "RayOptions", "WorkerOptions", "run_tasks"]
