"""The test simulator's integrator: semi-implicit (symplectic) Euler with gravity.

Shared by ``collres_sim`` live and offline so both produce the same input
states. ROS-free: numpy and the core's quaternion helpers only.
"""

from __future__ import annotations

import numpy as np

from collres_ros.core.rotation import integrate as integrate_orientation
from collres_ros.core.types import BodyStates


def euler_step(states: BodyStates, dynamic: np.ndarray, gravity: np.ndarray,
               dt: float, kinematic: np.ndarray | None = None) -> BodyStates:
    """States after ``dt`` s: v += g dt, then x += v dt, q rotated by omega dt (world frame).

    ``dynamic``: (N,) bool, static bodies keep their pose and zero twist.
    ``kinematic``: (N,) bool, static bodies that move at their prescribed,
    constant twist (no gravity): x += v dt, q rotated by omega dt.
    ``gravity``: (3,) m/s^2, world frame. Torque-free bodies keep their
    world angular velocity (no gyroscopic term: the test scenes do not need it).
    """
    dynamic = np.asarray(dynamic, bool)
    driven = np.zeros_like(dynamic) if kinematic is None else np.asarray(kinematic, bool)
    driven = driven & ~dynamic
    moving = (dynamic | driven)[:, None]
    accelerated = dynamic[:, None]
    linear = np.where(moving, states.linear + np.where(accelerated, np.asarray(gravity, float)
                                                       * dt, 0.0), 0.0)
    angular = np.where(moving, states.angular, 0.0)
    position = states.position + linear * dt
    orientation = np.where(moving, integrate_orientation(states.orientation, angular, dt),
                           states.orientation)
    return BodyStates(position, orientation, linear, angular)


def stamp_velocity(linear: np.ndarray, gravity: np.ndarray, dt: np.ndarray | float
                   ) -> np.ndarray:
    """The linear velocity at a state's stamp from the twist ``euler_step`` reports, m/s.

    ``euler_step`` writes v_n = v_(n-1) + g dt, then x_n = x_(n-1) + v_n dt: v_n is
    the mean velocity over the step that ended at the stamp, i.e. the velocity at its
    middle, t_n - dt/2, of the parabola through the positions (the core reads input
    twists the same way and answers in kind). Under the constant gravity of the step
    the velocity at the stamp t_n is therefore v_n + g dt / 2, and with it
    1/2 m |v|^2 - m g.x is exactly constant in free flight. ``linear``: (..., 3), world
    frame; ``dt``: the step length, s, broadcast against ``linear[..., 0]``. Angular
    velocity needs no such shift (no torque in the integrator).
    """
    dt = np.asarray(dt, float)[..., None]
    return np.asarray(linear, float) + np.asarray(gravity, float) * (0.5 * dt)
