"""Matplotlib drawings of coverage episodes (imported lazily: matplotlib is optional)."""

from __future__ import annotations

from typing import Any

import gymnasium
import numpy as np

from marl_cover.graph import SpatialGraph

WAYPOINT_COLOUR = "#c8c8c8"
INTEREST_COLOUR = "#f28e2b"
COVERED_COLOUR = "#59a14f"


def _pyplot(interactive: bool):  # noqa: ANN202 (matplotlib module)
    try:
        import matplotlib
    except ImportError as error:
        raise ImportError(
            "rendering needs matplotlib, which is not installed "
            "(pip install 'marl-cover[render]' or pip install matplotlib)"
        ) from error

    if not interactive:
        matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    return plt


def draw_map(
    ax,  # noqa: ANN001 (matplotlib Axes)
    graph: SpatialGraph,
    robot_node: np.ndarray,
    interest: np.ndarray,
    visited: np.ndarray,
    trails: np.ndarray | None = None,
    robot_xy: np.ndarray | None = None,
    trail_xy: np.ndarray | None = None,
    discovered: np.ndarray | None = None,
) -> None:
    """Draws waypoints, points of interest (orange, green once covered), trails and robots.

    In exploration (``discovered`` given) what the team has not discovered is drawn faded.

    Args:
        ax: A matplotlib ``Axes``.
        graph: The map.
        robot_node: ``(R,)`` waypoint of each robot.
        interest: ``(N,)`` bool, points of interest.
        visited: ``(N,)`` bool, visited waypoints.
        trails: ``(T + 1, R)`` waypoints of each robot over time, or ``None``.
        robot_xy: ``(R, 2)`` robot positions in metres (robots off the waypoints); overrides
            ``robot_node``.
        trail_xy: ``(T, R, 2)`` past positions in metres; overrides ``trails``.
        discovered: ``(N,)`` bool, waypoints known to the team (``None``: all).
    """
    import matplotlib.pyplot as plt

    pos = graph.positions
    senders, receivers = graph.edge_index
    from matplotlib.collections import LineCollection

    known = np.ones(graph.num_nodes, dtype=bool) if discovered is None else discovered
    known_edge = known[senders] & known[receivers]
    size = max(2.0, 4000.0 / max(graph.num_nodes, 1))
    for nodes, edges, alpha in ((known, known_edge, 1.0), (~known, ~known_edge, 0.2)):
        keep = edges & (senders < receivers)
        segments = np.stack([pos[senders[keep]], pos[receivers[keep]]], axis=1)
        ax.add_collection(
            LineCollection(
                list(segments), colors=WAYPOINT_COLOUR, linewidths=0.5, alpha=alpha, zorder=0
            )
        )
        ax.scatter(
            *pos[nodes & ~interest].T, s=size * 0.3, c=WAYPOINT_COLOUR, alpha=alpha, zorder=1
        )
        ax.scatter(
            *pos[nodes & interest & ~visited].T, s=size, c=INTEREST_COLOUR, alpha=alpha, zorder=2
        )
    ax.scatter(*pos[interest & visited].T, s=size, c=COVERED_COLOUR, alpha=0.5, zorder=2)
    colours = plt.get_cmap("tab10")(np.arange(len(robot_node)) % 10)
    if trail_xy is None and trails is not None:
        trail_xy = pos[trails]  # (T + 1, R, 2)
    if trail_xy is not None and len(trail_xy) > 1:
        for r in range(len(robot_node)):
            ax.plot(*trail_xy[:, r].T, color=colours[r], linewidth=1.5, alpha=0.8, zorder=3)
    robot_xy = pos[robot_node] if robot_xy is None else robot_xy
    ax.scatter(*robot_xy.T, s=size * 4, c=colours, edgecolors="black", zorder=4)
    ax.set_aspect("equal")
    ax.autoscale_view()
    ax.set_xticks([])
    ax.set_yticks([])


def figure_to_array(fig) -> np.ndarray:  # noqa: ANN001 (matplotlib Figure)
    """The RGB pixels of a drawn figure, ``(H, W, 3)`` uint8."""
    fig.canvas.draw()
    return np.asarray(fig.canvas.buffer_rgba())[..., :3].copy()


class Renderer:
    """Keeps one figure per environment and redraws it each call."""

    def __init__(self, mode: str, size_inches: float = 6.0) -> None:
        self.mode = mode
        self._plt = _pyplot(interactive=mode == "human")
        self.fig, self.ax = self._plt.subplots(figsize=(size_inches, size_inches), dpi=100)
        if mode == "human":
            self._plt.ion()

    def draw(
        self,
        graph: SpatialGraph,
        robot_node: np.ndarray,
        interest: np.ndarray,
        visited: np.ndarray,
        trails: np.ndarray,
        title: str = "",
        robot_xy: np.ndarray | None = None,
        discovered: np.ndarray | None = None,
    ) -> np.ndarray | None:
        """Redraws the episode; returns the pixels in ``"rgb_array"`` mode.

        ``robot_xy`` ``(R, 2)`` draws the robots at these positions (robots between waypoints).
        """
        self.ax.clear()
        draw_map(
            self.ax,
            graph,
            robot_node,
            interest,
            visited,
            trails,
            robot_xy=robot_xy,
            discovered=discovered,
        )
        self.ax.set_title(title)
        if self.mode == "rgb_array":
            return figure_to_array(self.fig)
        self.fig.canvas.draw_idle()
        self.fig.canvas.flush_events()
        return None

    def close(self) -> None:
        """Closes the figure."""
        self._plt.close(self.fig)


class EpisodeRendering:
    """``render`` and ``close`` of the coverage environments (mixed into
    :class:`marl_cover.env.CoverageEnv`, which holds the episode state they draw)."""

    # the episode state it draws, held by the environment
    render_mode: str | None
    config: Any
    _renderer: Any
    _robot_node: np.ndarray  # (R,)
    _interest: np.ndarray  # (N,) bool
    _visited: np.ndarray  # (N,) bool
    _trails: list[np.ndarray]  # (R,) each
    _discovery: Any  # marl_cover.discovery.Discovery in exploration, else None
    _num_steps: int

    def _episode_map(self) -> SpatialGraph:
        raise NotImplementedError

    def render(self) -> np.ndarray | None:
        """Draws the map, the points of interest, the robots and their trails.

        Returns an ``(H, W, 3)`` uint8 image in ``"rgb_array"`` mode, ``None`` otherwise.
        """
        if self.render_mode is None:
            gymnasium.logger.warn("render() called without a render_mode; nothing drawn")
            return None
        graph = self._episode_map()
        if self._renderer is None:
            self._renderer = Renderer(self.render_mode)
        return self._renderer.draw(
            graph,
            self._robot_node,
            self._interest,
            self._visited,
            np.stack(self._trails),
            title=f"{self._progress_text()}   "
            f"covered {int((self._interest & self._visited).sum())}/{int(self._interest.sum())}"
            + self._discovery_text(),
            robot_xy=self._robot_xy(),
            discovered=None if self._discovery is None else self._discovery.discovered,
        )

    def _discovery_text(self) -> str:
        if self._discovery is None:
            return ""
        return f"   discovered {self._discovery.num_discovered}/{self._episode_map().num_nodes}"

    def _progress_text(self) -> str:
        return f"step {self._num_steps}/{self.config.max_steps}"

    def _robot_xy(self) -> np.ndarray | None:
        """Where to draw the robots (``None``: on their waypoints)."""
        return None

    def close(self) -> None:
        """Closes the render window, if any."""
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None
