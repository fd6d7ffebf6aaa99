"""The resolution pipeline: body inputs of one stamp in, corrected states and contacts out.

``Resolver`` is the one place that calls ``World.step``; the node, the offline
sim and the replay tool all go through it, so they give the same answers.
It keeps every body's last good (corrected) state and stamp, the states as one (N, 13)
array of rows (position, orientation, linear, angular: the wire's order), so that a step's
gathers, scatters and copies are one array operation each, whatever N; and it:

* validates the inputs (``validation.check_inputs``); a refused body is held
  at its last good state (inactive: infinite mass this step) and reported; an input
  stamped at or behind its body's last stamp is refused and changes nothing (the next
  good input is answered bit for bit as if it never came), unless the step before was
  refused behind at an older stamp: the source's clock runs on from an earlier time (a
  new run), and its bodies start fresh;
* previous = the body's last corrected state, current = its input; a body seen
  for the first time, in a new run of its source, after a gap longer than
  ``settings.max_dt`` or after missing the previous step starts fresh
  (previous = current, its warm-start entries forgotten; one resumed forward, after a
  gap or a missed step, keeps its last answer's twist as the one before the step); but
  when every such body resumes forward asleep, within one period's reach of its held pose,
  nothing restarts: the step is the usual one of the stream's last period from the held
  states, and the sleep rule judges the inputs (``_resumes_asleep``);
* static bodies take their params pose unless it is published; a dynamic body
  never published yet sits, inactive, at its params pose;
* dt = stamp - the previous step's stamp; when there is no usable previous
  step every body is fresh and ``FRESH_DT`` is used (nothing moves between
  identical previous and current poses), or the last usable step's length when every
  fresh body resumes forward (its twist's change spans one period of its source);
* returns the corrected states of every accepted input body (never NaN; a
  non-finite result keeps the input and is reported ``non_finite_result``),
  the contacts with absolute time of impact (ns) and the rejections.

Deterministic: the same sequence of calls gives bit-identical results.
No ROS import: numpy and the core only.
"""

from __future__ import annotations

import time
from collections import Counter
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Optional, Protocol, Sequence

import numpy as np

from collres_ros.core.config import NodeSettings, SolverSettings
from collres_ros.core.types import (
    BodyInput, BodySpec, BodyStates, CollisionFilter, ContactReport, InputBatch,
    Rejection)
from collres_ros.core.validation import (
    NO_STAMP, NameIndex, StampCheck, check_inputs, check_stamps, stale_bodies)

if TYPE_CHECKING:
    from collres_ros.core.world import World

FRESH_DT = 1e-3            # s, dt given to the world when no body has a usable previous state
DEFAULT_STALE_TIMEOUT = 1.0  # s


@dataclass
class ResolvedStep:
    """Everything one step produced; K output bodies, M contacts."""

    stamp_ns: int
    names: list[str]                  # (K) accepted input bodies, in input order
    index: np.ndarray                 # (K,) body index in the scene
    states: BodyStates                # (K) corrected states, world frame
    twist_in_body: np.ndarray         # (K,) bool: the input twist was in the body frame
    body_names: tuple[str, ...]       # all N names: contacts' body_a/body_b index these
    report: ContactReport             # M solved contacts (body indices, world frame)
    # the step's span (ns) the contacts' toi fractions are of: 0 when every contact is from
    # the step's start (a fresh step); ``toi_ns`` of it
    toi_span_ns: int
    rejected: list[Rejection] = field(default_factory=list)  # refused inputs (bodies held)
    # accepted after a gap or with time going back: a fresh start, unless ``resumed_asleep``
    resets: list[Rejection] = field(default_factory=list)
    stale: list[str] = field(default_factory=list)           # bodies silent > stale timeout
    dt: float = 0.0                   # s, step length used (fresh start: FRESH_DT or the period)
    step_time_s: float = 0.0          # wall time of resolve() (not deterministic)
    world_time_s: float = 0.0         # wall time of World.step alone (not deterministic)
    # CPU time of this thread in World.step (not deterministic): below world_time_s by the
    # time the thread waited for a core (preempted by other threads or processes)
    world_cpu_s: float = 0.0
    # (N, 7) every body's pose after the step (scene order, world frame): position of the
    # centre of mass (m), orientation x, y, z, w; static and held bodies included
    poses: np.ndarray = field(default_factory=lambda: np.zeros((0, 7)))
    # (broad-phase pairs, contact rows) the step budget (solver.max_pairs, max_contacts)
    # dropped: the deepest were kept; (0, 0) within the budget
    budget: tuple[int, int] = (0, 0)
    # (K,) bool: the body's island sleeps (answered with its held pose, zero twist)
    sleeping: np.ndarray = field(default_factory=lambda: np.zeros(0, bool))
    number: int = 0                   # the resolver's steps so far, this one included
    # the report is step ``number - 1``'s, array for array (``StepResult.unchanged``)
    unchanged: bool = False
    # (K, 13) the corrected states as rows (position, orientation, linear, angular: the
    # wire's order); ``states`` are its column views
    values: np.ndarray = field(default_factory=lambda: np.zeros((0, 13)))
    # the gap's bodies (``resets``, all large_gap) resumed asleep from their held states: the
    # usual step of the stream's period, no fresh start (``Resolver._resumes_asleep``)
    resumed_asleep: bool = False

    _toi_ns: Optional[np.ndarray] = field(default=None, init=False, repr=False)

    @property
    def toi_ns(self) -> np.ndarray:
        """(M,) int64 absolute time of impact of each contact, ns (computed when first read:
        nothing is spent on it for a step whose contacts nobody reads)."""
        if self._toi_ns is None:
            toi = np.asarray(self.report.contacts.toi, float)
            span_ns, stamp_ns = self.toi_span_ns, self.stamp_ns
            if span_ns and toi.any():
                self._toi_ns = stamp_ns - np.rint((1.0 - toi) * span_ns).astype(np.int64)
            else:   # every contact from the step's start (persistent, held asleep)
                self._toi_ns = np.full(len(toi), stamp_ns - span_ns, np.int64)
        return self._toi_ns

    def contact_names(self, k: int) -> tuple[str, str]:
        """Body names (A, B) of contact ``k``."""
        c = self.report.contacts
        return self.body_names[int(c.body_a[k])], self.body_names[int(c.body_b[k])]


class SceneLike(Protocol):
    """What a Resolver reads of a scene (``ros/params.Scene`` is one)."""

    @property
    def world_frame(self) -> str: ...
    @property
    def bodies(self) -> Sequence[BodySpec]: ...
    @property
    def initial(self) -> BodyStates: ...
    @property
    def solver(self) -> SolverSettings: ...
    @property
    def node(self) -> NodeSettings: ...
    @property
    def collision_filter(self) -> CollisionFilter: ...


class Resolver:
    """Stateful resolution of a stream of steps (see module docstring)."""

    def __init__(self, bodies: Sequence[BodySpec], settings: Optional[SolverSettings] = None,
                 *, world: Optional[World] = None, world_frame: str = 'world',
                 initial: Optional[BodyStates] = None,
                 stale_timeout: float = DEFAULT_STALE_TIMEOUT,
                 collision_filter: Optional[CollisionFilter] = None) -> None:
        """``bodies``: the scene's N bodies; ``initial``: their params states (world frame,
        default zeros); ``stale_timeout`` (s); ``collision_filter``: default every pair
        collides. ``world``: the World to step (default: a ``core.world.World`` of
        ``bodies``), for tests."""
        self.bodies = tuple(bodies)
        self.names = tuple(b.name for b in self.bodies)
        self._name_array = np.array(self.names, dtype=object)
        self.index_of = {name: i for i, name in enumerate(self.names)}
        self._lookup = NameIndex(self.index_of)
        self.world_frame = world_frame
        self.stale_timeout = stale_timeout
        self.dynamic = np.array([not b.static for b in self.bodies], bool)
        self._settings = settings or SolverSettings()
        if world is None:
            from collres_ros.core.world import World
            world = World(self.bodies, self._settings, collision_filter=collision_filter)
        self.world = world
        self.number = 0   # steps resolved (never reset: ``ResolvedStep.number``)
        # (N, 13) the params states as rows (position, orientation, linear, angular)
        self._no_stale = np.zeros(len(self.bodies), bool)
        self._no_stale.flags.writeable = False
        self._covered: tuple[object, bool] = (None, False)   # the last rows, and whether
        #                                                     they hold every dynamic body
        self._params_values = np.concatenate(_arrays(
            initial if initial is not None else BodyStates.zeros(len(self.bodies))), axis=1)
        self.reset()

    @classmethod
    def for_scene(cls, scene: SceneLike, world: Optional[World] = None) -> 'Resolver':
        """The resolver of a validated scene: its bodies, solver settings, frame, params
        states, stale timeout and collision filter."""
        return cls(scene.bodies, scene.solver, world=world, world_frame=scene.world_frame,
                   initial=scene.initial, stale_timeout=scene.node.stale_timeout,
                   collision_filter=scene.collision_filter)

    @property
    def state(self) -> BodyStates:
        """Every body's last good (corrected) state, or its params state before its first
        input: world frame, views of the resolver's (N, 13) rows (position, orientation,
        linear, angular), read-only by contract."""
        return _states(self._values)

    # --- runtime changes (take effect on the next step) -------------------------------------

    @property
    def settings(self) -> SolverSettings:
        return self._settings

    @settings.setter
    def settings(self, value: SolverSettings) -> None:
        self._settings = value
        self.world.settings = value

    @property
    def collision_filter(self) -> CollisionFilter:
        return self.world.collision_filter

    @collision_filter.setter
    def collision_filter(self, value: CollisionFilter) -> None:
        """Which pairs may collide from the next step on."""
        self.world.collision_filter = value

    def set_material(self, name: str, **values: Optional[float]) -> None:
        """Change a body's material coefficients by name (``World.set_material``; values
        already validated by the caller)."""
        self.world.set_material(self.index_of[name], **values)

    def sleep_counts(self) -> dict[str, int]:
        """Dynamic bodies awake and asleep, islands awake (last step) and asleep; empty
        when sleeping is off."""
        if not self._settings.sleeping:
            return {}
        counts = self.world.sleep.counts()
        return {'awake_bodies': int(self.dynamic.sum()) - counts['sleeping_bodies'], **counts}

    def reset(self) -> None:
        """Forget all history: every body back to its params state, never seen."""
        self._values = self._params_values.copy()
        self.last_stamp = np.full(len(self.bodies), NO_STAMP, np.int64)
        # the scene rows the last step stamped, all of them (with previous_step_ns): the
        # same object again (an input of the same names) needs no comparison of stamps
        self._stamped: object = None
        self.previous_step_ns = NO_STAMP
        # the stamp of the last step, if every input of it was refused behind its body's
        # last stamp (``NO_STAMP`` otherwise): a later one behind too is a new run
        self.behind_ns = NO_STAMP
        self.period_ns = 0   # length of the last usable step (ns; 0: none yet)
        self.totals: Counter[str] = Counter()
        if len(self.bodies):
            self.world.forget(np.arange(len(self.bodies)))

    def restart(self) -> None:
        """Forget every body's history (a new run of the source), keep the totals."""
        totals = self.totals
        self.reset()
        self.totals = totals

    # --- one step ---------------------------------------------------------------------------

    def resolve(self, stamp_ns: int, inputs: Sequence[BodyInput] | InputBatch) -> ResolvedStep:
        """Resolve one step at ``stamp_ns`` (ns) from the bodies' inputs (list or arrays)."""
        start = time.perf_counter()
        stamp_ns = int(stamp_ns)
        settings = self._settings
        # 1. validate: refused inputs are reported, their bodies held
        checked = check_inputs(inputs, self._lookup, self.world_frame)
        rejected = list(checked.rejected)
        # rows: the scene rows of the inputs, a slice when they are consecutive (block copies)
        index, rows = checked.index, checked.rows
        history = check_stamps(self.last_stamp[rows], stamp_ns, int(settings.max_dt * 1e9),
                               self.previous_step_ns, rows is self._stamped)
        fresh = history.fresh
        entered = checked.values             # (K, 13) the accepted inputs, world frame
        twist_in_body = checked.twist_in_body
        resets: list[Rejection] = []
        held = False   # every fresh body resumes asleep: the usual step of the period
        if not history.usual and (fresh.any() or history.repeated.any()):   # not the usual step
            for k in np.flatnonzero(history.repeated):
                name = self.names[checked.index[k]]
                rejected.append(Rejection(name, 'repeated_stamp',
                                          f'{name}: already resolved at stamp {stamp_ns} ns'))
            # a stamp behind the body's last one is refused and changes nothing (a timing
            # glitch), unless a step before it was refused so and is older: the source's
            # clock runs on from an earlier time (a new run), its bodies start fresh
            new_run = NO_STAMP < self.behind_ns < stamp_ns
            refused = history.repeated if new_run else history.repeated | history.backwards
            if not new_run:
                for k in np.flatnonzero(history.backwards):
                    rejected.append(self._backwards(checked.index[k], stamp_ns, 'refused'))
            held = self._resumes_asleep(checked.index, checked.values,
                                        history.fresh & ~refused, stamp_ns)
            resets = self._resets(checked.index, history, stamp_ns, new_run)
            use = ~refused
            if not use.all():
                index, fresh, entered = index[use], fresh[use], entered[use]
                twist_in_body, rows = twist_in_body[use], index
            if held:
                fresh = np.zeros(len(index), bool)
            if not len(index) and refused.any():
                # every input already resolved at this stamp (a message delivered twice) or
                # behind it: nothing to step; a world step of nothing was a fresh one, which
                # woke every sleeping island and dropped the warm start
                if history.backwards.any():
                    self.behind_ns = stamp_ns
                return self._repeated(stamp_ns, rejected, start)
        self.behind_ns = NO_STAMP

        # 2. previous and current states of all N bodies: (N, 13) rows, one array each;
        # previous is the history itself unless a fresh start changes it (the world only
        # reads it)
        current = self._values.copy()
        current[rows] = entered
        previous = self._values
        if not history.usual and fresh.any():   # previous = current: nothing moved before
            restart = index[fresh]
            previous = previous.copy()
            previous[restart] = current[restart]
            # a body resumed forward (after a gap or a missed step) keeps its last answer's
            # twist as the one before the step: its input's twist less that is the change
            # its source integrated over the step (an asleep pile's input after a gap, g dt
            # down, is its supports' load, as on the usual step, not a fall of every body
            # into them that a 1 ms solve of the pile cannot stop); a body first seen or
            # whose time went back has no such twist (previous = its input)
            resumed = fresh & (self.last_stamp[index] != NO_STAMP) \
                & (self.last_stamp[index] < stamp_ns)
            previous[index[resumed], 7:13] = self._values[index[resumed], 7:13]
            # each moves in this step from where it was held (its last answer, or its params
            # state): its island and what it sweeps wake, no other island
            self.world.forget(restart, self._values[restart, 0:7])
            resumed_all = bool(resumed[fresh].all())
        else:
            resumed_all = False
        active = ~self.dynamic
        active[rows] = True
        step_ns = stamp_ns - self.previous_step_ns
        if held and not 0 < step_ns <= settings.max_dt * 1e9:
            step_ns = self.period_ns   # the held states' next step
        usable = (self.previous_step_ns != NO_STAMP and 0 < step_ns
                  and step_ns <= settings.max_dt * 1e9 and not fresh.all())
        # a step without a usable previous one: FRESH_DT, but when every fresh body resumes
        # forward, the stream's last step length (the change of twist its source integrated
        # spans one of its periods; over 1 ms that change is a load 1 / (period * 1 ms)
        # times gravity's that a cold solve of a pile does not hold)
        dt = step_ns * 1e-9 if usable else (
            self.period_ns * 1e-9 if resumed_all and self.period_ns else FRESH_DT)
        if usable:
            self.period_ns = step_ns

        # 3. the world step
        world_start, world_cpu = time.perf_counter(), time.thread_time()
        with np.errstate(over='ignore', invalid='ignore'):   # the guard below reports it
            result = self.world.step(previous, current, dt, active, fresh=not usable)
        world_time = time.perf_counter() - world_start
        world_cpu = time.thread_time() - world_cpu
        out = result.values   # (N, 13)
        # one guard, one report: a body the world repaired or that is still non-finite (a
        # finite sum of every number is the usual step's whole test)
        repaired = {r.body for r in result.rejected if r.reason == 'non_finite_result'}
        if repaired or not np.isfinite(out.sum()):
            bad = ~np.isfinite(out[index]).all(axis=1)
            if repaired:
                bad |= np.isin(self._name_array[index], list(repaired))
            for i in index[bad]:
                rejected.append(Rejection(self.names[i], 'non_finite_result',
                                          f'{self.names[i]}: the solver produced a non-finite '
                                          'state; the input is passed through'))
        else:
            bad = None   # every result finite
        rejected += [r for r in result.rejected if r.reason != 'non_finite_result']

        # 4. keep the corrected states as the history of the next step; the answer's rows
        if bad is not None and bad.any():
            self._values[index[~bad]] = out[index[~bad]]
            self._values[index[bad]] = current[index[bad]]
            values = self._values[rows].copy()   # (K, 13)
        else:
            bad = None
            values = out[rows]   # (K, 13), of this step's own array
            self._values[rows] = values
        self.last_stamp[rows] = stamp_ns
        self.previous_step_ns = stamp_ns
        self._stamped = rows

        # 5. report
        report = result.report
        # a body stamped now is not stale: when the step's input holds every dynamic body,
        # none is (a stream's usual step)
        stale = self._no_stale if self._covers_dynamic(rows) else stale_bodies(
            self.last_stamp, stamp_ns, int(self.stale_timeout * 1e9), self.dynamic)
        self.totals['steps'] += 1
        self.number += 1
        self.totals['contacts'] += report.contacts.count
        budget = self.world.budget
        if any(budget):
            self.totals['contact_budget'] += 1   # steps over the budget
        if rejected or resets:
            self.totals.update(r.reason for r in rejected + resets)
        names = list(self.names[rows]) if isinstance(rows, slice) else \
            self._name_array[rows].tolist()
        return ResolvedStep(stamp_ns, names, index, _states(values), twist_in_body,
                            self.names, report, step_ns if usable else 0, rejected, resets,
                            [self.names[i] for i in np.flatnonzero(stale)] if stale.any()
                            else [], dt,
                            time.perf_counter() - start, world_time, world_cpu,
                            self._values[:, 0:7].copy(), budget,
                            np.zeros(len(index), bool) if result.sleeping is None
                            else result.sleeping[rows] if bad is None
                            else result.sleeping[rows] & ~bad,
                            number=self.number, unchanged=result.unchanged, values=values,
                            resumed_asleep=held)

    def _repeated(self, stamp_ns: int, rejected: list[Rejection], start: float
                  ) -> ResolvedStep:
        """The answer to an input whose every body was already resolved at ``stamp_ns``:
        no body, no contact, the refusals counted; the history is untouched."""
        self.number += 1
        self.totals.update(r.reason for r in rejected)
        return ResolvedStep(stamp_ns, [], np.zeros(0, np.int64),
                            BodyStates.zeros(0), np.zeros(0, bool), self.names,
                            ContactReport.empty(), 0, rejected,
                            step_time_s=time.perf_counter() - start,
                            poses=self._values[:, 0:7].copy(), number=self.number)

    def _covers_dynamic(self, rows: np.ndarray | slice) -> bool:
        """Whether the scene rows ``rows`` (an input's, the same object step after step for
        the same names) hold every dynamic body."""
        if self._covered[0] is not rows:
            held = np.zeros(len(self.bodies), bool)
            held[rows] = True
            self._covered = (rows, not (self.dynamic & ~held).any())
        return self._covered[1]

    def _resumes_asleep(self, index: np.ndarray, entered: np.ndarray, fresh: np.ndarray,
                        stamp_ns: int) -> bool:
        """Whether every fresh body of this step (``fresh`` of ``index``, the inputs not refused;
        ``entered``, the (K, 13) input rows, world frame) resumes forward (a gap or a missed step,
        not time going back nor a first input) asleep, within a period's reach, after a usable step
        of known length: its island is held at rest, so the step is the usual one of that length
        from the held states, and the sleep rule judges the inputs against them (a source that kept
        integrating the rest sends the held state advanced by one period, gravity's g dt and g
        dt^2: the island stays asleep, answered at rest; anything else wakes it, as on a usual
        step). A restart instead would solve every body cold from its input, sunk g dt^2 and moving
        at g dt into its supports, and shake the pile awake."""
        sleep = self.world.sleep
        if not self.period_ns or not sleep.enabled or not fresh.any():
            return False
        resumed = index[fresh]
        last = self.last_stamp[resumed]
        if not ((last != NO_STAMP).all() and (last < stamp_ns).all()
                and sleep.asleep[resumed].all()):
            return False
        # and each input within one period's reach of its held pose (the sleep rule's own
        # bound): a body moved during the gap restarts there, with no sweep across the gap
        moved = np.linalg.norm(entered[fresh, 0:3] - self._values[resumed, 0:3], axis=1)
        reach = (np.linalg.norm(entered[fresh, 7:10], axis=1)
                 + self._settings.sleep_threshold) * self.period_ns * 1e-9
        return bool((moved <= reach).all())

    def _backwards(self, i: int, stamp_ns: int, what: str) -> Rejection:
        """Body ``i``'s input stamped behind its last one; ``what`` became of it."""
        name = self.names[i]
        return Rejection(name, 'time_backwards', f'{name}: stamp {stamp_ns} ns is older than '
                         f'its last one {self.last_stamp[i]} ns; {what}')

    def _resets(self, index: np.ndarray, history: StampCheck, stamp_ns: int, new_run: bool
                ) -> list[Rejection]:
        """This step's inputs after a gap or, in a new run of the source, with time going
        back, reported (fresh starts, unless the gap's bodies resume asleep:
        ``ResolvedStep.resumed_asleep``)."""
        resets = [self._backwards(index[k], stamp_ns, 'a new run of the source: history '
                                  'reset') for k in np.flatnonzero(history.backwards & new_run)]
        for k in np.flatnonzero(history.gap & ~history.backwards):
            name = self.names[index[k]]
            gap = (stamp_ns - self.last_stamp[index[k]]) * 1e-9
            resets.append(Rejection(name, 'large_gap',
                                    f'{name}: {gap:.3g} s since its last state (> max_dt '
                                    f'{self._settings.max_dt:g} s)'))
        return resets


def _arrays(states: BodyStates) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The four arrays of ``states`` (position, orientation, linear, angular), in place."""
    return states.position, states.orientation, states.linear, states.angular


def _states(values: np.ndarray) -> BodyStates:
    """BodyStates whose four arrays are the column views of (N, 13) ``values`` (position,
    orientation, linear, angular): writes to either are writes to both."""
    return BodyStates(values[:, 0:3], values[:, 3:7], values[:, 7:10], values[:, 10:13])
