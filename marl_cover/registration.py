"""Registration of the environments in PettingZoo's registry under versioned ids."""

from __future__ import annotations

#: Registered ids: ``pettingzoo.make("parallel", id, **config)`` or ``make("aec", id, ...)``.
ENV_IDS = ("marl_cover/Coverage-v0", "marl_cover/CoverageQuadrotor-v0")


def register_envs() -> None:
    """Registers every id of :data:`ENV_IDS` in the parallel and AEC registries (idempotent)."""
    from pettingzoo.env_registry.registration import aec_registry, parallel_registry, register

    entry_points = {
        "marl_cover/Coverage-v0": "marl_cover.env",
        "marl_cover/CoverageQuadrotor-v0": "marl_cover.continuous",
    }
    for env_id, module in entry_points.items():
        if env_id not in parallel_registry:
            register("parallel", env_id, entry_point=f"{module}:parallel_env")
        if env_id not in aec_registry:
            register("aec", env_id, entry_point=f"{module}:env")
