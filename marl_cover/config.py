"""Typed, validated configuration of the coverage environment."""

from __future__ import annotations

import dataclasses
import functools
import numbers
import os
import types
import typing
from dataclasses import dataclass, field
from typing import Any, TypeVar

import numpy as np

from marl_cover.graph import SpatialGraph

#: Named maps: a procedural city (new each reset), windows of the paper's map (new each reset),
#: the paper's 1266-waypoint graph, and its 5659-waypoint graph.
MAP_PRESETS = ("city", "paper", "paper_full", "paper_large")
INVALID_ACTION_MODES = ("noop", "raise")
#: ``coverage``: the whole map is known; ``exploration``: robots discover it with a range sensor.
TASKS = ("coverage", "exploration")
RENDER_MODES = ("human", "rgb_array")

T = TypeVar("T")


def require(*checks: tuple[bool, str], prefix: str = "") -> None:
    """Raises ``ValueError(prefix + message)`` for the first ``(ok, message)`` that is not ok:
    the range checks of the configs' ``__post_init__``."""
    for ok, message in checks:
        if not ok:
            raise ValueError(prefix + message)


def check_field_types(config: Any) -> None:
    """Checks the fields of dataclass ``config`` against their annotations.

    Covers the annotations configs use: ``int``, ``float`` (an ``int`` is accepted), ``bool``,
    ``str``, ``X | None`` and ``tuple``/``list`` of those; numpy numbers count as Python ones,
    a ``bool`` is not a number, and other annotations (nested configs, graphs) are not checked.

    Raises:
        TypeError: a field holds a value of another type, naming the class, the field, the
            expected type and the value.
    """
    check_values(
        type(config), {f.name: getattr(config, f.name) for f in dataclasses.fields(config)}
    )


def check_values(cls: type, values: dict[str, Any]) -> None:
    """:func:`check_field_types` on ``values`` meant for the fields of dataclass ``cls``, before
    it is built (keys that are not fields are left to the constructor).

    Raises:
        TypeError: as :func:`check_field_types`.
    """
    hints = _type_hints(cls)
    for name, value in values.items():
        if name in hints and not _matches(value, hints[name]):
            raise TypeError(
                f"{cls.__name__}.{name} must be {_describe(hints[name])}, got {value!r} "
                f"({type(value).__name__})"
            )


@functools.cache
def _type_hints(cls: type) -> dict[str, Any]:
    hints = typing.get_type_hints(cls)
    return {f.name: hints[f.name] for f in dataclasses.fields(cls) if f.name in hints}


def _matches(value: Any, hint: Any) -> bool:
    origin, args = typing.get_origin(hint), typing.get_args(hint)
    if origin in (typing.Union, types.UnionType):
        return any(_matches(value, arg) for arg in args)
    if origin in (tuple, list):
        if not isinstance(value, (tuple, list)):
            return False
        if origin is tuple and args and args[-1] is not Ellipsis:
            return len(value) == len(args) and all(map(_matches, value, args))
        return not args or all(_matches(item, args[0]) for item in value)
    if hint is type(None):
        return value is None
    if hint is bool:
        return isinstance(value, (bool, np.bool_))
    if hint in (int, float):
        if isinstance(value, (bool, np.bool_)):
            return False
        return isinstance(value, numbers.Integral if hint is int else numbers.Real)
    if hint is str:
        return isinstance(value, str)
    return True  # nested configs, graphs, Any: checked where they are built


def _describe(hint: Any) -> str:
    if typing.get_origin(hint) in (typing.Union, types.UnionType):
        return " or ".join(_describe(arg) for arg in typing.get_args(hint))
    if hint is type(None):
        return "None"
    return {int: "an integer", float: "a number", bool: "true or false", str: "a string"}.get(
        hint, str(hint)
    )


def config_from_dict(cls: type[T], values: dict[str, Any]) -> T:
    """Builds dataclass ``cls`` from ``values``; an unknown key is an error that names it.

    Raises:
        TypeError: a key is not a field of ``cls``.
    """
    names = {f.name for f in dataclasses.fields(cls)}  # type: ignore[arg-type]
    unknown = sorted(set(values) - names)
    if unknown:
        raise TypeError(f"unknown {cls.__name__} key(s) {unknown}; valid keys are {sorted(names)}")
    return cls(**values)


@dataclass(frozen=True)
class EnvSettings:
    """The settings of an environment that a file or a command line can hold (every field of
    :class:`CoverageConfig` but the ready-made ``graph`` and the ``render_mode``); the
    command line's ``env`` sections (``env.map=paper env.num_robots=10``).

    Attributes:
        task: ``"coverage"`` (the map is known from the start) or ``"exploration"`` (waypoints
            become known within ``sensor_range`` of a robot; see :mod:`marl_cover.discovery`).
        sensor_range: Exploration: range of each robot's sensor in metres (the paper's 22 m),
            measured from its waypoint; at least the longest edge of the map.
        num_robots: Team size.
        max_steps: Actions per episode, T (the paper's code gave T - 1; we give T).
        hops: Radius K of each robot's ego-graph.
        interest_fraction: Fraction of the waypoints drawn as points of interest at each reset.
        start_density: Robots start on distinct waypoints of a breadth-first ball of at least
            ``start_density * num_robots`` waypoints around a random waypoint.
        allow_swaps: Whether two robots may exchange waypoints along one edge in one step.
        invalid_action: What a masked-out action does: ``"noop"`` (the robot stays and its
            ``infos["invalid_action"]`` is 1) or ``"raise"`` (``ValueError`` naming the robot).
        map: ``"city"``, ``"paper"``, ``"paper_full"``, ``"paper_large"``, or a path to an
            occupancy grid (``.npy`` or an image; a ``pathlib.Path`` is stored as a string).
        city_size: Waypoints of each procedural city (``map="city"``).
        map_perimeter: For a grid file: keep free cells within this many cells of an obstacle
            (``None``: every free cell).
        map_cell_size: For a grid file: cell size in metres.
        window_fraction: For a grid file: draw a random window of this fraction of the bounding
            box per axis at each reset (``None``: the whole map). For ``map="paper"``: the
            fraction of its windows (``None``: the paper's 1/3).
        min_window_nodes: Smallest window accepted, in waypoints.
        ego_backend: How ego-graphs are built: ``"auto"`` (``"numba"`` if installed, else
            ``"numpy"``), ``"numpy"`` or ``"numba"``; all give identical observations.
        observation_mode: ``"padded"`` (fixed-shape arrays with masks) or ``"compact"`` (the
            same ego-graphs unpadded, views into step-wide tables: for large teams; see
            :mod:`marl_cover.compact`).
        max_observation_bytes: Refuse, when the environment is made, a configuration whose
            observations of one step could need more bytes than this (the padded arrays, or
            the compact tables' worst case); ``None``: no limit.
    """

    task: str = "coverage"
    sensor_range: float = 22.0
    num_robots: int = 4
    max_steps: int = 50
    hops: int = 19
    interest_fraction: float = 0.5
    start_density: int = 5
    allow_swaps: bool = True
    invalid_action: str = "noop"
    map: str = "city"
    city_size: int = 228
    map_perimeter: float | None = None
    map_cell_size: float = 5.0
    window_fraction: float | None = None
    min_window_nodes: int = 200
    ego_backend: str = "auto"
    observation_mode: str = "padded"
    max_observation_bytes: int | None = 4 * 2**30

    def __post_init__(self) -> None:
        if isinstance(self.map, os.PathLike):  # a grid file given as a Path
            object.__setattr__(self, "map", os.fspath(self.map))
        check_field_types(self)
        require(*self._checks())

    def _checks(self) -> list[tuple[bool, str]]:
        return [
            (self.task in TASKS, f"task must be one of {TASKS}, got {self.task!r}"),
            (self.sensor_range > 0, f"sensor_range must be > 0 metres, got {self.sensor_range}"),
            (self.num_robots >= 1, f"num_robots must be >= 1, got {self.num_robots}"),
            (self.max_steps >= 1, f"max_steps must be >= 1, got {self.max_steps}"),
            (self.hops >= 1, f"hops must be >= 1, got {self.hops}"),
            (
                0.0 <= self.interest_fraction <= 1.0,
                f"interest_fraction must be in [0, 1], got {self.interest_fraction}",
            ),
            (self.start_density >= 1, f"start_density must be >= 1, got {self.start_density}"),
            (
                self.invalid_action in INVALID_ACTION_MODES,
                f"invalid_action must be one of {INVALID_ACTION_MODES}, "
                f"got {self.invalid_action!r}",
            ),
            (self.city_size >= 1, f"city_size must be >= 1, got {self.city_size}"),
            (self.map_cell_size > 0, f"map_cell_size must be > 0 metres, got {self.map_cell_size}"),
            (
                self.map_perimeter is None or self.map_perimeter >= 0,
                f"map_perimeter must be >= 0 cells or null, got {self.map_perimeter}",
            ),
            (
                self.min_window_nodes >= 1,
                f"min_window_nodes must be >= 1, got {self.min_window_nodes}",
            ),
            (
                self.window_fraction is None or 0.0 < self.window_fraction <= 1.0,
                f"window_fraction must be in (0, 1], got {self.window_fraction}",
            ),
            (
                self.ego_backend in ("auto", "numpy", "numba"),
                f"ego_backend must be 'auto', 'numpy' or 'numba', got {self.ego_backend!r}",
            ),
            (
                self.observation_mode in ("padded", "compact"),
                f"observation_mode must be 'padded' or 'compact', got {self.observation_mode!r}",
            ),
            (
                self.max_observation_bytes is None or self.max_observation_bytes > 0,
                f"max_observation_bytes must be > 0 or null, got {self.max_observation_bytes}",
            ),
        ]

    @classmethod
    def from_dict(cls, values: dict[str, Any]) -> EnvSettings:
        """See :func:`config_from_dict`."""
        return config_from_dict(cls, values)

    def as_kwargs(self) -> dict[str, Any]:
        """The settings as keyword arguments of :func:`marl_cover.parallel_env`."""
        return {f.name: getattr(self, f.name) for f in dataclasses.fields(EnvSettings)}


@dataclass(frozen=True)
class CoverageConfig(EnvSettings):
    """Configuration of :class:`marl_cover.env.CoverageEnv` (defaults: the paper's setting):
    every field of :class:`EnvSettings`, and

    Attributes:
        graph: A ready-made map; overrides ``map``.
        render_mode: ``None``, ``"human"`` or ``"rgb_array"``.
    """

    graph: SpatialGraph | None = field(default=None, repr=False)
    render_mode: str | None = None

    def _checks(self) -> list[tuple[bool, str]]:
        return [
            *super()._checks(),
            (
                self.render_mode is None or self.render_mode in RENDER_MODES,
                f"render_mode must be None or one of {RENDER_MODES}, got {self.render_mode!r}",
            ),
            (
                self.graph is None or isinstance(self.graph, SpatialGraph),
                f"graph must be a SpatialGraph, got {type(self.graph).__name__}",
            ),
        ]

    @classmethod
    def from_dict(cls, values: dict[str, Any]) -> CoverageConfig:
        """See :func:`config_from_dict`."""
        return config_from_dict(cls, values)
