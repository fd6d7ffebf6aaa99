"""The core's one entry point: ``World.step`` resolves the contacts of one step.

One step maps the states of N bodies at the previous time and at the current
time (both world frame, before resolution) to corrected current states:

* bodies without contact keep their ``current`` state untouched, and so do
  pairs the collision filter drops (``CollisionFilter``): they pass through
  one another;
* a body with an impact (IMPACT/TUNNELLED contact, or a persistent contact
  that closes during the step faster than the restitution threshold) is
  rewound to its earliest time of impact f (lerp/slerp), solved with the
  velocity it had then, and advanced for the rest of the step, (1 - f) dt,
  with its new velocity under the step's constant external acceleration
  a = (current - previous twist) / dt (e.g. gravity);
* a state's twist is read as the velocity over the step that led to it, as
  semi-implicit Euler writes it (x1 = x0 + v1 dt: v1 is the mid-step
  velocity), so the velocity at fraction f is v1 + (f - 1/2) a dt, and the
  output twist of an impacted body is again the mid-step velocity; with this
  reading a bounce conserves the integrator's energy and gives the e^2 law;
* a body in persistent contact only is solved with its current velocity and
  its pose is the previous pose advanced by the new velocity for dt (so a
  resting box stays put);
* then penetrations beyond ``linear_slop`` are pushed out by split impulses
  (pose only, no velocity: no energy gain);
* last, a body whose motion from its previous pose to its answer goes deeper into
  a fixed shape than it was, by more than the slop (a body that turns far in a step
  takes its corners along arcs the rows do not follow), is held at the latest pose of
  that motion before, at rest (``Detection.hold_back``, as Box2D v3's continuous step); a
  sphere with an impact in the step keeps its twist (no corner of it follows an arc), any
  other sphere the part of it that its held motion travels.

Static bodies (and inactive ones, for this step) have zero inverse mass and
inertia: their ``current`` twist is a kinematic velocity, their state is
returned as given.

The resting solve runs in ceil(dt / ``settings.max_substep``) substeps after the one
detection (``StepSolver::soft_step``): a 30 Hz step is solved as 5 of 1/150 s.

Islands at rest sleep (``core.sleep``, ``settings.sleeping``): a sleeping body is answered
with its held pose and zero twist, left out of detection and solve, until something
wakes its island in the step.

Detection (``Detection.detect``) finds the contacts; everything that is
per-contact work after it (reference frame, prepare, warm start, iterations,
restitution, stored impulses, corrected poses, split-impulse push-out and
contact states) is one call into the compiled core (``_native.StepSolver``,
``src/step.h``) on whole arrays, without copies and with the GIL released.
"""

from __future__ import annotations

import math
import time
from typing import Protocol, Sequence

import numpy as np

from collres_ros.core import _native
from collres_ros.core.config import SOLVER_TUNING, SolverSettings
from collres_ros.core.detection import DETECTION_ONLY, Detection
from collres_ros.core.rotation import slerp
from collres_ros.core.shapes import mass_properties
from collres_ros.core.sleep import Sleep
from collres_ros.core.types import (BodySpec, BodyStates, CollisionFilter, ContactKind,
                                    ContactReport, ContactState, ContactSet, Rejection, StepResult)


class Detector(Protocol):
    """What the world needs from detection (``Detection`` is the real one)."""

    settings: SolverSettings
    collision_filter: CollisionFilter
    budget: tuple[int, int]   # last detect: (pairs, rows) the step budget dropped
    thread_runs: tuple[int, int, int, int]   # the second thread's part (Detection.thread_runs)

    def detect(self, previous: BodyStates, current: BodyStates,
               active: np.ndarray | None = None, threads: int = 1,
               dt: float = 0.0) -> ContactSet: ...


class World:
    """A fixed list of bodies, their materials, the solver settings and the warm-start cache."""

    def __init__(self, bodies: Sequence[BodySpec], settings: SolverSettings,
                 detector: Detector | None = None,
                 collision_filter: CollisionFilter | None = None) -> None:
        """``detector`` replaces coal detection (tests feed hand-made ContactSets).

        ``collision_filter``: which pairs may collide (default: every pair).
        """
        self.specs = list(bodies)
        self._collision = detector if detector is not None else \
            Detection(self.specs, settings, collision_filter)
        if detector is not None and collision_filter is not None:
            detector.collision_filter = collision_filter
        props = [mass_properties(spec) for spec in self.specs]
        self.inv_mass = np.array([p[0] for p in props], dtype=float)           # (N,) 1/kg
        self.inv_inertia_body = np.array([p[1] for p in props]).reshape(-1, 3, 3)
        self.dynamic = np.array([not s.static for s in self.specs]) & (self.inv_mass > 0.0)
        self.dynamic.flags.writeable = False   # the movable bodies of a step of every body
        # the last step's movable bodies and their masses for the solver (_masses)
        self._masked: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
        # the last step's answer: (its states, the (N, 13) rows they are column views of)
        self._answer: tuple[BodyStates, np.ndarray] = (BodyStates.zeros(0), np.zeros((0, 13)))
        self._all = np.ones(0, bool)   # every body active (_everyone)
        # a sphere's radius (m), 0 for any other shape: the solver aims a contact of two
        # spheres along the line of their centres on its own path (StepSolver::aim)
        self.radius = np.array([s.size[0] if s.shape == 'sphere' else 0.0
                                for s in self.specs], float)
        self._round = self.radius > 0.0
        self.restitution = np.array([s.restitution for s in self.specs], dtype=float)
        self.static_friction = np.array([s.static_friction for s in self.specs], dtype=float)
        self.kinetic_friction = np.array([s.kinetic_friction for s in self.specs], dtype=float)
        self.rolling_resistance = np.array([s.rolling_resistance for s in self.specs], float)
        self.torsional_friction = np.array([s.torsional_friction for s in self.specs], float)
        self._solver = _native.StepSolver()
        self._cache = self._solver.cache      # impulses of the last step, by pair and feature
        self.sleep = Sleep(self.specs, self.dynamic, settings)
        self.settings = settings
        # last step: detection and solve time (s), velocity sweeps done, solver rows
        # last step: (broad-phase pairs, contact rows) the step budget dropped (max_pairs,
        # max_contacts); (0, 0) within it
        self.budget: tuple[int, int] = (0, 0)
        self.timing: dict[str, float] = {'detect': 0.0, 'solve': 0.0, 'iterations': 0,
                                         'rows': 0}

    @property
    def settings(self) -> SolverSettings:
        return self._settings

    @settings.setter
    def settings(self, settings: SolverSettings) -> None:
        """New settings take effect at the next step."""
        self._settings = settings
        self._collision.settings = settings
        self._params = solver_params(settings)
        self.sleep.settings = settings       # wakes every island

    @property
    def collision_filter(self) -> CollisionFilter:
        return self._collision.collision_filter

    @collision_filter.setter
    def collision_filter(self, value: CollisionFilter) -> None:
        """Which pairs may collide from the next step on (detection drops the others);
        wakes every island."""
        self._collision.collision_filter = value
        self.sleep.wake_all()

    def set_material(self, index: int, **values: float | None) -> None:
        """Change one body's coefficients, by name: restitution, static_friction,
        kinetic_friction, rolling_resistance, torsional_friction (taken as valid: the
        caller checks ranges; None leaves one as it is); wakes every island."""
        for name, value in values.items():
            if name not in MATERIALS:
                raise TypeError(f'set_material: unknown coefficient {name!r}')
            if value is not None:
                getattr(self, name)[index] = value
        self.sleep.wake_all()

    @property
    def threads(self) -> int:
        """Threads of detection and of the solve (``SOLVER_TUNING`` ``threads``)."""
        return int(self._params.threads)

    @property
    def thread_runs(self) -> tuple[int, int, int, int]:
        """The second thread's part in the steps so far (``threads`` 2), detection's and the
        solve's: (runs posted for two threads, of those the ones the cost model ran paired
        (the second thread woken; the others ran on the calling thread alone), the chunks
        of the runs, of those the chunks the second thread ran: about half of a paired
        run's where it took its share, fewer where it was woken late or not given a core).
        Not deterministic (wall-time costs choose the mode); the answer's bits do not depend
        on it."""
        runs = self._collision.thread_runs
        paired, posted = self._solver.runs
        helped, chunks = self._solver.helped
        return (runs[0] + int(posted), runs[1] + int(paired), runs[2] + int(chunks),
                runs[3] + int(helped))

    def forget(self, bodies: np.ndarray, last_poses: np.ndarray | None = None) -> None:
        """Drop the warm-start impulses of these body indices (a fresh restart, a reset):
        each moves in the next step from ``last_poses`` ((K, 7) position m, orientation
        x y z w, world frame: where it was last; default its pose in that step), so a
        dynamic one's island wakes and the islands it sweeps or a static one's move touches
        wake (``Sleep.restart``); no other island wakes."""
        bodies = np.asarray(bodies, np.int64).ravel()
        self._cache.forget(bodies)
        self.sleep.restart(bodies, last_poses)

    def step(self, previous: BodyStates | np.ndarray, current: BodyStates | np.ndarray,
             dt: float, active: np.ndarray | None = None, fresh: bool = False) -> StepResult:
        """Resolve the contacts of the step previous -> current (dt > 0, s).

        ``previous``/``current``: all N bodies, world frame, before resolution
        (validated by the caller), as BodyStates or as (N, 13) float64 rows (position,
        orientation, linear, angular: the resolver's, read only, never copied whole; the
        compiled calls read their column views). ``active`` (N,) bool, False = quarantined:
        held at ``current`` with zero twist and infinite mass this step, its
        output state is ``current`` unchanged. Returns corrected states of all
        bodies, the solved contacts and non-finite results that were refused.
        ``fresh``: no usable previous step (``dt`` is nominal): neither this step nor
        the next is warm started from stored impulses, and neither is a step longer
        than ``settings.max_dt`` or one whose dt differs from the last by more than
        ``SOLVER_TUNING`` ``warm_start_ratio``.
        """
        previous, current = self._rows(previous), self._rows(current)
        active = self._everyone(len(current)) if active is None else np.asarray(active, bool)
        asleep = None
        if self._settings.sleeping:   # sleepers: held state, inactive (fixed for detection)
            current, active, asleep = self.sleep.before(previous, current, active, dt, fresh)
        # held (inactive) bodies: previous = current (a sleeper's previous state is already
        # its held one: its last answer); none when every body is active (``_everyone``)
        held = None if active is self._all else ~active if asleep is None else ~active & ~asleep
        if held is not None and held.any():
            previous = previous.copy()
            previous[held] = current[held]
        warm = self._settings.warm_start and dt <= self._settings.max_dt and not fresh
        self.timing = {'detect': 0.0, 'solve': 0.0, 'iterations': 0, 'rows': 0, 'substeps': 1}
        self.budget = (0, 0)
        rejected: list[Rejection] = []
        values, answer, report = self._resolve(previous, current, active, dt, warm, rejected)
        self._answer = (answer, values)
        report, sleeping, unchanged = self._settle(answer, report, active, dt, asleep)
        return StepResult(answer, report, rejected, sleeping, unchanged, values)

    def _rows(self, states: BodyStates | np.ndarray) -> np.ndarray:
        """(N, 13) float64 rows (position, orientation, linear, angular): ``states`` itself
        when it is such an array, the last step's answer's rows when ``states`` are its
        column views (as they were answered: a step fed its last answer builds no rows),
        else one new array of its four."""
        if isinstance(states, np.ndarray):
            return states if states.dtype == np.float64 else np.asarray(states, np.float64)
        answer, values = self._answer
        if (states.position is answer.position and states.orientation is answer.orientation
                and states.linear is answer.linear and states.angular is answer.angular):
            return values
        return np.concatenate(_arrays(states), axis=1, dtype=np.float64)

    def _everyone(self, count: int) -> np.ndarray:
        """(count,) bool, all True, read only: one array while the count holds."""
        if len(self._all) != count:
            self._all = np.ones(count, bool)
            self._all.flags.writeable = False
        return self._all

    def _resolve(self, previous_rows: np.ndarray, current_rows: np.ndarray,
                 active: np.ndarray, dt: float, warm: bool, rejected: list[Rejection]
                 ) -> tuple[np.ndarray, BodyStates, ContactReport]:
        """Detection and solve of the step previous -> current ((N, 13) rows): the
        answer's (N, 13) rows, its states (their column views) and its report; non-finite
        results refused are added to ``rejected``, times, sweeps and rows to ``timing``, the
        budget's drops to ``budget`` (the largest)."""
        started = time.perf_counter()
        previous, current = _states(previous_rows), _states(current_rows)
        # broad phase, narrow phase and time of impact (swept bounds, coal GJK/EPA, bisection);
        # without an active dynamic body every pair is of two fixed bodies: nothing to detect
        movable = self.dynamic if active is self._all else self.dynamic & active
        if not movable.any():
            self._cache.clear()
            return _unchanged(current_rows)
        contacts = _finite(self._collision.detect(previous, current, active,
                                                  self._params.threads, dt=dt))
        budget = self._collision.budget
        self.budget = (max(self.budget[0], budget[0]), max(self.budget[1], budget[1]))
        detected = time.perf_counter()
        self.timing['detect'] += detected - started
        if contacts.count == 0:
            self._cache.clear()
            return _unchanged(current_rows)
        # reference frame, prepare, warm start, iterate, restitution, store impulses,
        # advance poses, split-impulse push-out, contact states: one compiled call
        values = current_rows.copy()   # the answer, solved in place
        states = _states(values)
        report, sweeps, rows, substeps = self._solve(previous, current, states, contacts,
                                                     active, movable, dt, warm)
        self._hold_back(previous, states, active, report)
        # report: the final guard against non-finite output
        rejected += self._guard(values, current_rows)
        self.timing['solve'] += time.perf_counter() - detected
        self.timing['iterations'] += sweeps
        self.timing['rows'] += rows
        self.timing['substeps'] = substeps
        return values, states, report

    def _settle(self, states: BodyStates, report: ContactReport, active: np.ndarray,
                dt: float, asleep: np.ndarray | None
                ) -> tuple[ContactReport, np.ndarray | None, bool]:
        """Sleep timers and islands after the step (``core.sleep``): the report with the
        sleeping islands' held contacts, the bodies answered as asleep (None when sleeping
        is off) and whether the report is the last step's (``StepResult.unchanged``)."""
        if asleep is None:
            return report, None, False
        return self.sleep.after(states, self.dynamic & active, report, dt, asleep)

    def _solve(self, previous: BodyStates, current: BodyStates, out: BodyStates,
               contacts: ContactSet, active: np.ndarray, movable: np.ndarray, dt: float,
               warm: bool) -> tuple[ContactReport, int, int, int]:
        """The compiled solver step on whole arrays (no copy when dtypes and layout fit; the
        states' column views of (N, 13) rows are gathered by the binding): corrects ``out``
        (a copy of ``current``) in place; ``movable``: the active dynamic bodies.

        Returns the report, velocity sweeps done, solver rows and the resting solve's
        substeps.
        """
        inv_mass, inv_inertia_body = self._masses(movable)
        m = contacts.count
        report = ContactReport(ContactSet(contacts.body_a, contacts.body_b, contacts.point,
                                          contacts.normal, contacts.separation, np.empty(m),
                                          np.empty(m, np.int8), contacts.feature,
                                          contacts.manifolds, contacts.piece_a,
                                          contacts.piece_b),
                               np.empty(m), np.empty((m, 3)), np.empty(m, np.uint8))
        flat = (lambda array, dtype=np.float64: np.ascontiguousarray(array, dtype))
        sweeps, rows, substeps = self._solver.step(
            previous=_arrays(previous), current=_arrays(current), out=_arrays(out),
            inv_mass=inv_mass, inv_inertia_body=inv_inertia_body,
            movable=movable, held=~active, restitution=self.restitution,
            static_friction=self.static_friction, kinetic_friction=self.kinetic_friction,
            rolling_resistance=self.rolling_resistance,
            torsional_friction=self.torsional_friction, radius=self.radius,
            body_a=flat(contacts.body_a, np.int64), body_b=flat(contacts.body_b, np.int64),
            point=flat(contacts.point), normal=flat(contacts.normal),
            separation=flat(contacts.separation), toi=flat(contacts.toi),
            kind=flat(contacts.kind, np.int8), feature=flat(contacts.feature, np.int64),
            manifolds=flat(contacts.manifolds, np.int64),
            dt=float(dt), warm=warm, params=self._params, normal_impulse=report.normal_impulse,
            friction_impulse=report.friction_impulse, state=report.state,
            reported_toi=report.contacts.toi, reported_kind=report.contacts.kind)
        return report, sweeps, rows, substeps

    def _masses(self, movable: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(N,) inverse masses (1/kg) and (N, 3, 3) body-frame inverse inertias
        (1/(kg m^2)), zero for a body that does not move this step (``movable`` False):
        the last step's while the same bodies move (a pile: every step; their product
        over 10 N numbers cost 0.14 M instructions a step at N = 1000); ``dynamic`` itself
        (read only) when every body is active: known without a comparison."""
        last = self._masked
        if last is None or (last[0] is not movable and (
                last[0].shape != movable.shape or not (last[0] == movable).all())):
            self._masked = (movable, self.inv_mass * movable,
                            self.inv_inertia_body * movable[:, None, None])
        return self._masked[1], self._masked[2]

    def _hold_back(self, previous: BodyStates, states: BodyStates, active: np.ndarray,
                   report: ContactReport) -> None:
        """A body whose answer went deeper into a fixed shape than it was (by more than the
        slop) along its motion from ``previous`` is held at the latest pose of that motion
        before, at rest; a sphere struck in the step keeps its twist, any other sphere the
        part of it that its held motion travels (``Detection.hold_back``); a hand-made
        detector (tests) knows no shapes to hold it against."""
        hold_back = getattr(self._collision, 'hold_back', None)
        if hold_back is None:
            return
        fraction = hold_back(previous, states, active)
        if fraction.min() >= 1.0:   # the usual step: none held back
            return
        held = np.flatnonzero(fraction < 1.0)
        f = fraction[held, None]
        states.position[held] = previous.position[held] + f * (
            states.position[held] - previous.position[held])
        states.orientation[held] = slerp(previous.orientation[held], states.orientation[held],
                                         f[:, 0])
        # at rest, but for a sphere: its surface turns in place (no corner follows an arc).
        # One struck in the step keeps its twist (sent on into a wall, it keeps its energy:
        # the next step meets the wall); one without an impact is held by what it rolls on
        # (a ball rolling off a fixed ball, answered deeper each step as its speed grew):
        # its twist is the one its held motion travels with, else its pose stays while its
        # twist grows, and gains energy (0.5 kg ball, 30 Hz: +1.3 J in 14 steps)
        contacts = report.contacts
        impacted = np.zeros(len(fraction), bool)
        struck = (contacts.kind != ContactKind.PERSISTENT) | (report.state == ContactState.IMPACT)
        impacted[contacts.body_a[struck]] = impacted[contacts.body_b[struck]] = True
        round_ = self._round[held]
        turns = held[~round_]
        states.linear[turns], states.angular[turns] = 0.0, 0.0
        rolls = round_ & ~impacted[held]
        states.linear[held[rolls]] *= f[rolls]
        states.angular[held[rolls]] *= f[rolls]

    def _guard(self, values: np.ndarray, current: np.ndarray) -> list[Rejection]:
        """Bodies with a non-finite result ((N, 13) rows ``values``) keep their current input
        state; report them."""
        if math.isfinite(np.add.reduce(values, None)):   # the usual step (one sum is finite
            return []                                    # only when all its numbers are)
        rejected = []
        for i in np.flatnonzero(~np.isfinite(values).all(1)):
            values[i] = current[i]
            rejected.append(Rejection(self.specs[i].name, 'non_finite_result',
                                      'the solver produced a non-finite state; input kept'))
        return rejected


# the report of a step without contacts (its arrays are empty: shared by every such step)
NO_CONTACTS = ContactReport.empty()

MATERIALS = ('restitution', 'static_friction', 'kinetic_friction', 'rolling_resistance',
             'torsional_friction')


def solver_params(settings: SolverSettings) -> _native.SolverParams:
    """The compiled solver's parameters from the settings (combine rules by name)."""
    params = _native.SolverParams()
    for name in ('velocity_iterations', 'restitution_threshold', 'sticking_speed',
                 'linear_slop', 'position_correction', 'max_correction', 'max_substep'):
        setattr(params, name, getattr(settings, name))
    for spec in SOLVER_TUNING:
        if spec.name not in DETECTION_ONLY:
            setattr(params, spec.name, spec.default)
    params.restitution_rule = _native.CombineRule.__members__[settings.restitution_rule]
    params.friction_rule = _native.CombineRule.__members__[settings.friction_rule]
    return params


def combine(a: np.ndarray, b: np.ndarray, rule: str) -> np.ndarray:
    """One coefficient per contact from two bodies' (the solver's rule; per_object: mean)."""
    return np.asarray(_native.combine(np.asarray(a, float), np.asarray(b, float),
                                      _native.CombineRule.__members__[rule]), float)


def _arrays(states: BodyStates) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(position, orientation, linear, angular), as they are (views of (N, 13) rows)."""
    return states.position, states.orientation, states.linear, states.angular


def _unchanged(current: np.ndarray) -> tuple[np.ndarray, BodyStates, ContactReport]:
    """The answer of a step without contacts: a copy of the (N, 13) rows ``current``, its
    states and no contacts."""
    values = current.copy()
    return values, _states(values), NO_CONTACTS


def _states(values: np.ndarray) -> BodyStates:
    """BodyStates whose four arrays are the column views of (N, 13) ``values``."""
    return BodyStates(values[:, 0:3], values[:, 3:7], values[:, 7:10], values[:, 10:13])


def _finite(contacts: ContactSet) -> ContactSet:
    """Only the contacts whose numbers are all finite and whose normal is not zero.

    The normal's length is sqrt((x^2 + y^2) + z^2), the bits of np.linalg.norm(axis=1);
    the usual set (every number finite, every length above 0.5) is checked and its normals
    divided by their lengths in one compiled pass (``_native.usual_contacts``: the same
    divisions), any other row by row here."""
    unit = _native.usual_contacts(contacts.point, contacts.normal, contacts.separation,
                                  contacts.toi)
    if unit is not None:
        return ContactSet(contacts.body_a, contacts.body_b, contacts.point, unit,
                          contacts.separation, contacts.toi, contacts.kind, contacts.feature,
                          contacts.manifolds, contacts.piece_a, contacts.piece_b)
    n = np.asarray(contacts.normal, np.float64).reshape(-1, 3)
    square = n * n
    norm = np.sqrt((square[:, 0] + square[:, 1]) + square[:, 2])
    ok = (np.isfinite(contacts.point).all(1) & np.isfinite(norm) & (norm > 0.5)
          & np.isfinite(contacts.separation) & np.isfinite(contacts.toi))
    kept = contacts.select(ok)
    kept.normal /= norm[ok, None]
    return kept
