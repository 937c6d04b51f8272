"""marl-cover: multi-robot coverage and exploration on spatial graphs.

The front door is :func:`parallel_env` (PettingZoo ``ParallelEnv``) and :func:`env` (AEC);
:func:`quadrotor_parallel_env` is the same task with quadrotor-like robots in continuous time.
Importing this package needs only numpy, scipy, gymnasium and pettingzoo (pooch fetches the
paper's map on first use).
"""

from marl_cover.city import CityConfig, generate_city
from marl_cover.collisions import resolve_collisions
from marl_cover.config import CoverageConfig, EnvSettings
from marl_cover.continuous import DynamicsConfig, QuadrotorCoverageEnv
from marl_cover.continuous import env as quadrotor_env
from marl_cover.continuous import parallel_env as quadrotor_parallel_env
from marl_cover.dynamics import QuadrotorParams
from marl_cover.env import CoverageEnv, CoverageSnapshot, env, parallel_env
from marl_cover.graph import SpatialGraph
from marl_cover.maps import graph_from_occupancy, load_occupancy, paper_graph, sample_window
from marl_cover.paper_map import fetch_paper_map
from marl_cover.registration import ENV_IDS, register_envs

__version__ = "1.3.0"

__all__ = [
    "ENV_IDS",
    "CityConfig",
    "CoverageConfig",
    "CoverageEnv",
    "CoverageSnapshot",
    "DynamicsConfig",
    "EnvSettings",
    "QuadrotorCoverageEnv",
    "QuadrotorParams",
    "SpatialGraph",
    "env",
    "fetch_paper_map",
    "generate_city",
    "graph_from_occupancy",
    "load_occupancy",
    "paper_graph",
    "parallel_env",
    "quadrotor_env",
    "quadrotor_parallel_env",
    "register_envs",
    "resolve_collisions",
    "sample_window",
]

register_envs()
