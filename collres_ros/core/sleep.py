"""Sleeping islands: bodies at rest cost no detection and no solve (``src/islands.h``).

Bodies joined by the step's contacts (touching or within the speculative margin, impulse or
not, as Box2D v3's touching manifolds) form islands (static, kinematic and inactive bodies
never join one). A body is still while the speed of its farthest point,
|v| + |w| r (r its bounding radius about the centre of mass, m/s), stays below
``sleep_threshold``; an island whose bodies have all been still for ``time_to_sleep`` (s)
falls asleep, unless one of them is accelerating: its farthest point's speed has risen in
each of its last steps for ``rise_time`` times ``time_to_sleep`` (each rise more than
``rise_step`` times the threshold; ``config.SLEEP_TUNING``). A body at rest under balanced
loads has a speed that decays or jitters (round-off, the solve's residual); one that an
unbalanced load drives speeds up step after step however slowly, and by speed alone slept
before it reached the threshold: a ball from rest on a slope of tan = 1.1 mu_r (mu_r 0.05,
0.035 m/s^2) slept 4.4-5.0 mm down after 0.5 s where the law rolls it 17.5 mm in 1 s. Its
speed rises in every step (at tan = 1.01-1.1 mu_r, 30-240 Hz), while in the settling
100-body piles (seeds 1-2 of both kinds, 30 and 120 Hz) bodies under the threshold rose at
most 16-24 steps in a row at 30 Hz and 20-118 at 120 Hz while they settled, and such piles
(seeds 1-4) fall asleep as before (0.97-1.98 s) but two at 30 Hz one step and 0.2 s later
(mixed seeds 1 and 4: a ball rolls off the heap's top late).

A sleeping body is answered with its held pose (its last answer, the ``previous`` state)
and zero twist, which is the answer the solver gives a body at rest, and is left out of the
solve and of every pair detection queries (it is held as fixed).

It wakes, in the step:

* when its input departs from the held state beyond the threshold: a push (a velocity
  change other than the external acceleration it had when it fell asleep: upstream keeps
  integrating, so held twist + gravity dt does not wake it, nor the held state integrated
  k <= ``config.SLEEP_LATE_STEPS`` periods by it: an upstream integrating an answer that
  came late), a teleport or a correction (a pose the input velocity cannot reach from the
  held pose within the threshold);
* when the swept bounds of a moving body (kinematic, or awake and faster than the
  threshold, or jolted beyond it) touch its island, before detection: no impact is missed;
* after a step in which an awake body leaned on it (a contact with impulse): answered
  asleep (held) in that step, solved from the next;
* when an awake body comes back from a step without its input (held): it is taken as
  moving in that step, so its swept bounds wake the islands they touch (it may have left,
  while held, from under an island that fell asleep on it);
* when one of its bodies restarts fresh (a first input, a gap, time going back, a missed
  step: ``World.forget``): that body moves in the step from where it was held to its input,
  so its own island wakes and its swept bounds wake the islands they touch; no other (a
  static body restarted wakes what it touches when its pose changed or it has a twist, as
  on any step).

A body held for a step (no input: a message of some bodies; or its input refused) is fixed
in it, as a sleeper is: that wakes nothing, and an asleep body not mentioned stays asleep.

A woken body's still time restarts: it sleeps again only after ``time_to_sleep`` awake, so
a body answered asleep in two consecutive steps has the same pose in both (while
``time_to_sleep`` >= dt).
* everything wakes on a body added or removed, a material, filter or settings change,
  and a step without a usable previous one (a clock jump; not a gap after which
  every body resumes asleep within reach of its held pose: the resolver then steps the
  stream's period from the held states, ``Resolver._resumes_asleep``).

The contacts of a sleeping island (among its bodies and with static ones) are held as they
were in the step it fell asleep and reported every step with the state SLEEPING.

Frames: world. Units: SI.
"""

from __future__ import annotations

from typing import Sequence

import numpy as np

from collres_ros.core import _native
from collres_ros.core.config import SLEEP_LATE_STEPS, SLEEP_TUNING, SolverSettings
from collres_ros.core.shapes import bounding_radius
from collres_ros.core.types import BodySpec, BodyStates, ContactReport, ContactSet, ContactState


class Sleep:
    """The sleep state of a world's N bodies; ``before`` and ``after`` bracket a step."""

    def __init__(self, specs: Sequence[BodySpec], dynamic: np.ndarray,
                 settings: SolverSettings) -> None:
        self.dynamic = np.asarray(dynamic, bool)
        self._native = _native.Islands([bounding_radius(s) for s in specs],
                                       self.dynamic.astype(np.uint8).tolist())
        self._no_kinematic = np.zeros(len(self.dynamic), np.uint8)
        self._static = np.flatnonzero(~self.dynamic)     # may move: kinematic
        self._last_active: np.ndarray | None = None
        self._held = ContactReport.empty()    # contacts of the sleeping islands
        self._held_for = np.zeros(len(self.dynamic), bool)   # bodies asleep after last step
        self._version = 0   # of _held: counts its replacements
        self._restarted = np.zeros(len(self.dynamic), bool)   # movers of the next step
        self._restarted_from = np.zeros((len(self.dynamic), 7))   # their last poses (m, xyzw)
        self._reported: int | None = None   # _held's version when the last step's report
        #                                     was _held alone (None: it was not)
        self.settings = settings

    @property
    def settings(self) -> SolverSettings:
        return self._settings

    @settings.setter
    def settings(self, settings: SolverSettings) -> None:
        """New settings (a parameter change) wake everything."""
        self._settings = settings
        native = _native.SleepSettings()
        native.threshold = settings.sleep_threshold
        native.time_to_sleep = settings.time_to_sleep
        native.margin = settings.speculative_margin
        native.late_steps = SLEEP_LATE_STEPS
        for spec in SLEEP_TUNING:
            setattr(native, spec.name, spec.default)
        self._native.settings = native
        self.wake_all()

    @property
    def enabled(self) -> bool:
        return bool(self._settings.sleeping)

    def restart(self, bodies: np.ndarray, last_poses: np.ndarray | None = None) -> None:
        """The ``bodies`` (indices) restart fresh in the next step (their history
        forgotten), from ``last_poses`` ((K, 7) position m, orientation x y z w, world;
        default: their poses in that step). A dynamic one is a mover in that step, as a body
        back from held is: swept from its last pose, and a sleeper among them wakes its own
        island; a static (kinematic) one moves if its input's pose differs from its last or
        its twist is not zero, as on any step. Nothing else wakes for them."""
        self._restarted[bodies] = True
        self._restarted_from[bodies] = np.nan if last_poses is None else last_poses

    def wake_all(self) -> None:
        self._native.wake_all()
        self._restarted = np.zeros(len(self.dynamic), bool)   # none moves: all awake
        self._held = ContactReport.empty()
        self._version += 1
        self._held_for = np.zeros(len(self.dynamic), bool)

    @property
    def asleep(self) -> np.ndarray:
        """(N,) bool: the bodies asleep after the last step (read only)."""
        asleep = self._native.asleep.view(bool).copy()
        asleep.flags.writeable = False
        return asleep

    def counts(self) -> dict[str, int]:
        """Bodies and islands asleep, and awake islands of the last step."""
        return {'sleeping_bodies': self._native.sleeping_bodies,
                'sleeping_islands': self._native.sleeping_islands,
                'awake_islands': self._native.awake_islands}

    def before(self, previous: np.ndarray, current: np.ndarray, active: np.ndarray,
               dt: float, fresh: bool) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Wake what must wake, then (current, active, asleep): sleepers' current states
        replaced by their held state (previous pose, zero twist) and marked inactive.
        ``previous``, ``current``: (N, 13) rows (position, orientation, linear, angular)."""
        last = self._last_active
        kinematic = self._no_kinematic
        if fresh or last is None or len(last) != len(active):
            self.wake_all()            # a clock jump, a body added or removed
            self._last_active = active.copy()
        elif not (active == last).all():
            # a body held this step (not in the input, or refused) is fixed, as a sleeper is:
            # nothing wakes for it; an awake one back from held is a mover this step (it may
            # have lost a support while held), its swept bounds wake the islands they touch
            back = active & ~last & self.dynamic & ~self._native.asleep.view(bool)
            if back.any():
                kinematic = back.astype(np.uint8)
            self._last_active = active.copy()
        swept_from = previous
        if self._restarted.any():
            # a body restarted fresh moves in this step from where it was last (the step's
            # previous state is its input: nothing moved before); a sleeper's island wakes
            restarted, self._restarted = self._restarted, np.zeros(len(self.dynamic), bool)
            kinematic = kinematic | (restarted & active & self.dynamic)
            known = np.flatnonzero(restarted & np.isfinite(self._restarted_from).all(1))
            if len(known):
                swept_from = previous.copy()
                swept_from[known, 0:7] = self._restarted_from[known]
        if self._native.sleeping_bodies and len(self._static):
            k = self._static     # moved, or a kinematic velocity: a non-zero change of
            change = current[k]  # pose (finite numbers: a - b is 0 only where a == b) or twist
            change[:, 0:7] -= swept_from[k, 0:7]
            moved = active[k] & change.any(1)
            if moved.any():
                kinematic = kinematic.copy()
                kinematic[k] = moved
        self._native.wake(_columns(swept_from), _columns(current), active.view(np.uint8),
                          kinematic, float(dt))
        asleep = self._native.asleep.view(bool)
        if not asleep.any():
            return current, active, asleep
        held = current.copy()
        held[asleep, 0:7] = previous[asleep, 0:7]
        held[asleep, 7:13] = 0.0
        return held, active & ~asleep, asleep

    def after(self, out: BodyStates, movable: np.ndarray, report: ContactReport, dt: float,
              asleep: np.ndarray) -> tuple[ContactReport, np.ndarray, bool]:
        """Islands, timers and falling asleep from the step's answers ``out`` (islands that
        fall asleep get zero twist there). Returns the step's report with the held contacts
        of the islands answered as asleep appended (state SLEEPING), the (N,) bodies
        answered as asleep, and whether that report is the last step's (``StepResult.
        unchanged``: both were the held contacts alone, the same ones)."""
        contacts = report.contacts
        self._native.update(out.linear, out.angular, movable.astype(np.uint8),
                            np.ascontiguousarray(contacts.body_a, np.int64),
                            np.ascontiguousarray(contacts.body_b, np.int64),
                            np.ascontiguousarray(report.normal_impulse, np.float64), float(dt))
        now = self._native.asleep.view(bool)
        sleeping = asleep | now
        # the held contacts are those of the bodies asleep after the last step: all still
        # answered as asleep unless an island woke before this step's detection
        woke = bool((self._held_for & ~asleep).any())
        shown = _between(self._held, sleeping | ~self.dynamic) if woke else self._held
        # nothing awake touched anything: the report is the held contacts alone, unchanged
        # since the last step if that one's was too (the held arrays are never written)
        alone = not woke and not contacts.count
        unchanged = alone and self._reported == self._version
        self._reported = self._version if alone else None
        fell = now & ~asleep
        if woke or fell.any() or (asleep & ~now).any():
            kept = _between(self._held, now | ~self.dynamic)
            new = _between(report, fell | ~self.dynamic)   # held from now on, as persistent
            new.contacts.toi[:], new.contacts.kind[:] = 0.0, 0
            new.state[:] = ContactState.SLEEPING
            self._held = _joined(kept, new)
            self._version += 1
        self._held_for = now
        if shown.contacts.count:
            report = _joined(report, shown)
        return report, sleeping, unchanged


def _between(report: ContactReport, bodies: np.ndarray) -> ContactReport:
    """The contacts of ``report`` whose two bodies are both in the (N,) mask ``bodies``,
    each a copy."""
    c = report.contacts
    keep = bodies[np.asarray(c.body_a, np.int64)] & bodies[np.asarray(c.body_b, np.int64)] \
        if c.count else np.zeros(0, bool)
    return ContactReport(c.select(keep),
                         report.normal_impulse[keep], report.friction_impulse[keep],
                         report.state[keep])


def _joined(a: ContactReport, b: ContactReport) -> ContactReport:
    """The contacts of ``a`` then those of ``b``."""
    if not b.contacts.count:
        return a
    if not a.contacts.count:
        return b
    ca, cb = a.contacts, b.contacts
    return ContactReport(ContactSet.joined(ca, cb),
                         np.concatenate([a.normal_impulse, b.normal_impulse]),
                         np.concatenate([a.friction_impulse, b.friction_impulse]),
                         np.concatenate([a.state, b.state]))


def _columns(values: np.ndarray) -> tuple[np.ndarray, ...]:
    """(position, orientation, linear, angular): the column views of (N, 13) ``values``
    (the binding gathers them)."""
    return values[:, 0:3], values[:, 3:7], values[:, 7:10], values[:, 10:13]
