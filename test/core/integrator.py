"""A tiny integrator for the physics tests: gravity, semi-implicit Euler, the core every step.

Each step: ``current`` = the last corrected state integrated for dt
(v += g dt, x += v dt, q rotated by w dt), then ``World.step(previous,
current)`` with ``previous`` = the last corrected state, exactly as
collres_sim closes the loop.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Sequence

import numpy as np

from collres_ros.core.config import SolverSettings
from collres_ros.core.rotation import integrate, to_matrix
from collres_ros.core.shapes import mass_properties
from collres_ros.core.types import BodySpec, BodyStates, ContactState, StepResult
from collres_ros.core.world import World

GRAVITY = np.array([0.0, 0.0, -9.81])


@dataclass
class Trace:
    """What a run recorded, one row per step (after the step)."""

    time: list[float] = field(default_factory=list)
    position: list[np.ndarray] = field(default_factory=list)     # (N, 3)
    linear: list[np.ndarray] = field(default_factory=list)       # (N, 3)
    energy: list[float] = field(default_factory=list)            # J, kinetic + potential
    contacts: int = 0
    states: dict[int, int] = field(default_factory=dict)         # ContactState -> count
    friction: float = 0.0                                        # sum of |friction impulse|
    rejected: int = 0

    def positions(self) -> np.ndarray:
        return np.asarray(self.position)


class Simulation:
    """Bodies integrated with gravity and resolved by the core every step."""

    def __init__(self, bodies: Sequence[BodySpec], initial: BodyStates, rate_hz: float,
                 settings: SolverSettings | None = None,
                 gravity: np.ndarray = GRAVITY) -> None:
        self.world = World(bodies, settings or SolverSettings())
        self.state = initial.copy()
        self.dt = 1.0 / rate_hz
        self.gravity = np.asarray(gravity, float)
        self.dynamic = self.world.dynamic.copy()
        self.mass = np.where(self.dynamic, 1.0 / np.where(self.dynamic, self.world.inv_mass,
                                                          1.0), 0.0)
        self.inertia_body = np.array([_inertia(spec) for spec in bodies])
        self.time = 0.0

    def integrate(self, state: BodyStates) -> BodyStates:
        """Semi-implicit Euler for dt; static bodies keep their pose and twist."""
        move = self.dynamic[:, None]
        out = state.copy()
        out.linear = np.where(move, state.linear + self.gravity * self.dt, state.linear)
        out.position = np.where(move, state.position + out.linear * self.dt, state.position)
        out.orientation = np.where(move, integrate(state.orientation, state.angular, self.dt),
                                   state.orientation)
        return out

    def step(self) -> StepResult:
        current = self.integrate(self.state)
        result = self.world.step(self.state, current, self.dt)
        self.state = result.states
        self.time += self.dt
        return result

    def energy(self, state: BodyStates | None = None) -> float:
        """Total kinetic + potential energy of the dynamic bodies, J."""
        state = self.state if state is None else state
        rot = to_matrix(state.orientation)
        w_body = np.einsum('nji,nj->ni', rot, state.angular)
        kinetic = 0.5 * self.mass * np.sum(state.linear ** 2, axis=1) \
            + 0.5 * np.einsum('ni,ni->n', self.inertia_body, w_body ** 2)
        potential = -self.mass * (state.position @ self.gravity)
        return float(np.sum(np.where(self.dynamic, kinetic + potential, 0.0)))

    def run(self, duration: float, trace: Trace | None = None) -> Trace:
        trace = trace or Trace()
        for _ in range(int(round(duration / self.dt))):
            result = self.step()
            report = result.report
            trace.time.append(self.time)
            trace.position.append(self.state.position.copy())
            trace.linear.append(self.state.linear.copy())
            trace.energy.append(self.energy())
            trace.contacts += report.contacts.count
            for value in report.state.tolist():
                trace.states[value] = trace.states.get(value, 0) + 1
            trace.friction += float(np.sum(np.linalg.norm(report.friction_impulse, axis=1)))
            trace.rejected += len(result.rejected)
        return trace


def _inertia(spec: BodySpec) -> np.ndarray:
    """Principal moments (3,) kg m^2 (zeros for static bodies), from the core's shapes."""
    _, inv_inertia = mass_properties(spec)
    diag = np.diag(inv_inertia)
    return np.where(diag > 0.0, 1.0 / np.where(diag > 0.0, diag, 1.0), 0.0)


def count(trace: Trace, state: ContactState) -> int:
    return trace.states.get(int(state), 0)
