"""A stand-in for core.world.World that records its calls (pipeline tests without physics)."""

from __future__ import annotations

from typing import Any, Optional, Sequence

import numpy as np

from collres_ros.core.config import SolverSettings
from collres_ros.core.sleep import Sleep
from collres_ros.core.types import (
    BodySpec, BodyStates, ContactReport, ContactSet, Rejection, StepResult)


class FakeWorld:
    """Returns ``current`` (optionally changed by ``hook``) and the ``contacts`` it is given."""

    def __init__(self, bodies: Sequence[BodySpec], settings: Optional[SolverSettings] = None
                 ) -> None:
        self.bodies = list(bodies)
        self.settings = settings or SolverSettings()
        self.calls: list[dict[str, Any]] = []
        self.forgotten: list[list[int]] = []
        self.materials: dict[int, dict[str, Any]] = {}
        self.report: ContactReport = ContactReport.empty()
        self.hook: Any = None
        self.budget = (0, 0)   # what the step budget dropped (World.budget)
        # the sleep state a World has (World.sleep); the fake never steps it: every body awake
        self.sleep = Sleep(self.bodies, np.array([not b.static for b in self.bodies], bool),
                           self.settings)

    def set_material(self, index: int, **values: Any) -> None:
        self.materials[index] = values

    def forget(self, bodies: np.ndarray, last_poses: Optional[np.ndarray] = None) -> None:
        self.forgotten.append([int(i) for i in bodies])

    def step(self, previous: np.ndarray, current: np.ndarray, dt: float,
             active: Optional[np.ndarray] = None, fresh: bool = False) -> StepResult:
        """``previous``, ``current``: (N, 13) rows, as the resolver gives them."""
        self.calls.append({'previous': states_of(previous.copy()),
                           'current': states_of(current.copy()), 'dt': dt, 'fresh': fresh,
                           'active': None if active is None else active.copy(),
                           'settings': self.settings})
        values = current.copy()
        out = states_of(values)
        if self.hook is not None:
            self.hook(out)
        return StepResult(out, self.report, values=values)


def states_of(values: np.ndarray) -> BodyStates:
    """BodyStates whose arrays are the column views of (N, 13) ``values``."""
    return BodyStates(values[:, 0:3], values[:, 3:7], values[:, 7:10], values[:, 10:13])


def one_contact(a: int, b: int, toi: float) -> ContactReport:
    """A report with a single IMPACT contact between bodies a and b."""
    contacts = ContactSet(np.array([a]), np.array([b]), np.array([[0.0, 0.0, 0.0]]),
                          np.array([[0.0, 0.0, 1.0]]), np.array([-0.001]), np.array([toi]),
                          np.array([1], np.int8), np.array([0]), np.array([[a, b, 0, 1]]))
    return ContactReport(contacts, np.array([0.5]), np.array([[0.1, 0.0, 0.0]]),
                         np.array([1], np.uint8))


class GuardingWorld(FakeWorld):
    """A FakeWorld that guards its output as ``World`` does: a non-finite body is repaired
    (it keeps ``current``) and reported once as ``non_finite_result``."""

    def step(self, previous: np.ndarray, current: np.ndarray, dt: float,
             active: Optional[np.ndarray] = None, fresh: bool = False) -> StepResult:
        result = super().step(previous, current, dt, active, fresh)
        rows = result.values
        assert rows is not None
        rejected = []
        for i in np.flatnonzero(~np.isfinite(rows).all(axis=1)):
            rows[i] = current[i]
            rejected.append(Rejection(self.bodies[i].name, 'non_finite_result', 'input kept'))
        return StepResult(result.states, result.report, rejected, values=rows)
