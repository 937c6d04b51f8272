"""Quadrotor-like point-mass bodies tracking waypoints with a cascaded position controller.

Each robot is a 3-D double integrator with linear drag, driven by the acceleration its
actuators can produce, and a position controller of the kind that flies small quadrotors
(cascaded: a position loop gives a desired velocity, a velocity loop gives the commanded
acceleration):

    v_des = clip(k_p * (target - p), max_speed)                         # position loop
    u     = clip(k_v * (v_des - v) + (drag / mass) * v, max_accel)      # velocity loop + drag
    v'    = v + dt * (u - (drag / mass) * v)                            # body (semi-implicit
    p'    = p + dt * v'                                                 #  Euler)

``clip(x, c)`` scales a vector down to norm ``c``. ``u`` is what the actuators deliver, so its
norm never exceeds ``max_accel``. When ``dt * max(k_v, drag / mass) <= 1`` (checked), ``v'`` is
a convex combination of ``v``, ``v_des`` and ``0``, so the speed never exceeds ``max_speed``.
With infinite limits, no drag and ``k_p = k_v = 1 / dt`` the controller is dead-beat: a body
reaches its target in one step and stops there (the discrete environment's move).

Optional: Gaussian noise on the measured position the controller feeds back (``noise_std``,
metres) and an actuation delay (targets take effect ``delay`` seconds after they are sent).
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from marl_cover.config import check_field_types

#: Standard gravity, m/s^2.
GRAVITY = 9.81


@dataclass(frozen=True)
class QuadrotorParams:
    """Physical and controller parameters of one robot (SI units).

    Defaults: a ~0.7 kg quadrotor of the AscTec Hummingbird class (the airframe of the
    simulator the paper flew; mass with battery 0.71 kg) with a 20 degree tilt limit
    (horizontal acceleration ``g * tan(20 deg) = 3.6 m/s^2``), linear rotor drag 0.25 N s/m, and
    the 2 m/s speed cap of the paper's AirSim controller .

    Attributes:
        mass: Mass in kg.
        drag: Linear drag coefficient in N s/m (force ``-drag * v``).
        max_speed: Speed limit in m/s (``inf``: none).
        max_accel: Largest acceleration the actuators deliver, m/s^2 (``inf``: none).
        position_gain: ``k_p`` of the position loop, 1/s.
        velocity_gain: ``k_v`` of the velocity loop, 1/s.
        dt: Integration step in seconds.
    """

    mass: float = 0.71
    drag: float = 0.25
    max_speed: float = 2.0
    max_accel: float = GRAVITY * math.tan(math.radians(20.0))
    position_gain: float = 1.5
    velocity_gain: float = 4.0
    dt: float = 0.01

    def __post_init__(self) -> None:
        check_field_types(self)
        positive = ("mass", "max_speed", "max_accel", "position_gain", "velocity_gain", "dt")
        for name in positive:
            if not getattr(self, name) > 0:
                raise ValueError(f"QuadrotorParams.{name} must be > 0, got {getattr(self, name)}")
        if self.drag < 0:
            raise ValueError(f"QuadrotorParams.drag must be >= 0, got {self.drag}")
        stiffest = max(self.velocity_gain, self.drag / self.mass)
        if self.dt * stiffest > 1.0 + 1e-12:
            raise ValueError(
                f"dt * max(velocity_gain, drag / mass) = {self.dt * stiffest:.3g} must be <= 1 "
                "(the integration would overshoot the velocity loop)"
            )

    @classmethod
    def ideal(cls, dt: float = 0.01) -> QuadrotorParams:
        """Infinite speed and acceleration with dead-beat gains: every move takes one step."""
        return cls(
            mass=1.0,
            drag=0.0,
            max_speed=math.inf,
            max_accel=math.inf,
            position_gain=1.0 / dt,
            velocity_gain=1.0 / dt,
            dt=dt,
        )


def clip_norm(vectors: np.ndarray, limit: float) -> np.ndarray:
    """Scales each row of ``vectors`` ``(N, D)`` down to norm ``limit`` (no-op for ``inf``)."""
    if math.isinf(limit):
        return vectors
    squared = vectors[:, 0] * vectors[:, 0]  # (N,), summed left to right (as the kernel does)
    for column in range(1, vectors.shape[1]):
        squared = squared + vectors[:, column] * vectors[:, column]
    if squared.max() <= limit * limit:
        return vectors
    return vectors * np.minimum(1.0, limit / np.sqrt(squared + 1e-300))[:, None]


class QuadrotorTeam:
    """The bodies of a team, stepped together (positions and velocities ``(R, 3)``).

    Args:
        params: Parameters shared by the team.
        positions: Start positions ``(R, 3)`` in metres (at rest).
        noise_std: Standard deviation of the position measurement noise, metres.
        delay: Actuation delay in seconds (rounded to whole steps).
        rng: Generator of the measurement noise (required when ``noise_std > 0``).
        backend: ``"numpy"`` (the reference), ``"numba"`` (a compiled kernel, the same bits)
            or ``"auto"`` (``"numba"`` when installed).
    """

    def __init__(
        self,
        params: QuadrotorParams,
        positions: np.ndarray,
        noise_std: float = 0.0,
        delay: float = 0.0,
        rng: np.random.Generator | None = None,
        backend: str = "auto",
    ) -> None:
        if noise_std < 0 or delay < 0:
            raise ValueError(f"noise_std and delay must be >= 0, got {noise_std} and {delay}")
        if noise_std > 0 and rng is None:
            raise ValueError("noise_std > 0 needs a generator (rng)")
        self.params = params
        self.position = np.array(positions, dtype=np.float64)  # (R, 3)
        if self.position.ndim != 2 or self.position.shape[1] != 3:
            raise ValueError(f"positions must have shape (R, 3), got {self.position.shape}")
        self.velocity = np.zeros_like(self.position)  # (R, 3)
        self.acceleration = np.zeros_like(self.position)  # (R, 3), last actuator command
        self.noise_std = noise_std
        self._rng = rng
        delay_steps = round(delay / params.dt)
        # Targets sent but not yet acting; the oldest acts now.
        self._pipeline: deque[np.ndarray] = deque(
            [self.position.copy() for _ in range(delay_steps + 1)], maxlen=delay_steps + 1
        )
        self._drag_rate = params.drag / params.mass
        kernels = compiled_kernels(backend)
        self._kernel = kernels.advance_team if kernels is not None else None

    @property
    def num_robots(self) -> int:
        """Number of bodies."""
        return len(self.position)

    def measure(self) -> np.ndarray:
        """Measured positions ``(R, 3)``: the true ones plus the measurement noise."""
        if self.noise_std == 0:
            return self.position
        return self.position + self._noise(self.position.shape)

    def _noise(self, shape: tuple[int, ...]) -> np.ndarray:
        """Measurement noise of ``shape`` (a generator is required whenever ``noise_std > 0``)."""
        assert self._rng is not None
        return self._rng.normal(0.0, self.noise_std, shape)

    def step(self, targets: np.ndarray) -> None:
        """Sends ``targets`` ``(R, 3)`` and advances every body by one ``dt``."""
        self.advance(targets, 1)

    def advance(self, targets: np.ndarray, steps: int, track: np.ndarray | None = None) -> None:
        """Holds ``targets`` ``(R, 3)`` for ``steps`` steps of ``dt``.

        Args:
            targets: Target of each body, metres.
            steps: Integration steps.
            track: Optional ``(steps, R, 3)`` array that receives the positions after each step.
        """
        p = self.params
        targets = np.asarray(targets, dtype=np.float64)
        if self._kernel is not None:
            self._advance_compiled(self._kernel, targets, steps, track)
            return
        drag_rate, dt = self._drag_rate, p.dt
        position, velocity = self.position, self.velocity
        acceleration = self.acceleration
        for k in range(steps):
            self._pipeline.append(targets)
            measured = position if self.noise_std == 0 else self.measure()
            v_des = clip_norm(p.position_gain * (self._pipeline[0] - measured), p.max_speed)
            command = p.velocity_gain * (v_des - velocity) + drag_rate * velocity
            acceleration = clip_norm(command, p.max_accel)
            velocity = velocity + dt * (acceleration - drag_rate * velocity)
            position = position + dt * velocity
            self.position = position
            if track is not None:
                track[k] = position
        self.velocity, self.acceleration = velocity, acceleration

    def _advance_compiled(
        self, kernel: Callable[..., None], targets: np.ndarray, steps: int, track: np.ndarray | None
    ) -> None:
        """:meth:`advance` by the compiled kernel: the targets acting at each step and the
        noise of each measurement are laid out first (the noise drawn in one call, the same
        numbers as one call per step)."""
        if steps <= 0:
            return
        p, r = self.params, self.num_robots
        acting = np.empty((steps, r, 3))  # the oldest target in the pipeline at each step
        old = list(self._pipeline)[1:]  # targets sent earlier that still wait
        for k in range(min(steps, len(old))):
            acting[k] = old[k]
        acting[len(old) :] = targets
        self._pipeline.extend([targets] * min(steps, len(self._pipeline)))  # full: maxlen
        noise = np.empty((0, r, 3))  # (steps, R, 3) with noise, else none
        if self.noise_std > 0:
            noise = self._noise((steps, r, 3))
        position, velocity = self.position.copy(), self.velocity.copy()
        acceleration = np.empty_like(position)
        out = track if track is not None else np.empty((steps, r, 3))
        kernel(
            position,
            velocity,
            acceleration,
            acting,
            noise,
            p.position_gain,
            p.velocity_gain,
            self._drag_rate,
            p.dt,
            p.max_speed,
            p.max_accel,
            out,
        )
        self.position, self.velocity, self.acceleration = position, velocity, acceleration


#: Implementations of :meth:`QuadrotorTeam.advance`.
DYNAMICS_BACKENDS = ("auto", "numpy", "numba")


def compiled_kernels(backend: str):  # noqa: ANN201 (a module or None)
    """The module of compiled kernels for ``backend`` (``marl_cover._dynamics_numba``), or
    ``None`` for numpy.

    Raises:
        ValueError: an unknown backend, or ``"numba"`` without numba installed.
    """
    if backend not in DYNAMICS_BACKENDS:
        raise ValueError(f"dynamics backend must be one of {DYNAMICS_BACKENDS}, got {backend!r}")
    if backend == "numpy":
        return None
    try:
        from marl_cover import _dynamics_numba
    except ImportError:
        if backend == "numba":
            raise ValueError(
                "dynamics backend 'numba' needs the numba package (pip install numba)"
            ) from None
        return None
    return _dynamics_numba
