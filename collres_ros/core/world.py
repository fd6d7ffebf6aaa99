"""The core's one entry point: ``World.step`` resolves the contacts of one step.

One step maps the states of N bodies at the previous time and at the current
time (both world frame, before resolution) to corrected current states:

* bodies without contact keep their ``current`` state untouched;
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
  (pose only, no velocity: no energy gain).

Static bodies (and inactive ones, for this step) have zero inverse mass and
inertia: their ``current`` twist is a kinematic velocity, their state is
returned as given.
"""

from __future__ import annotations

import time
from typing import Protocol, Sequence

import numpy as np

from collres_ros.core import rotation, solver
from collres_ros.core.combine import combine_friction, restitution_per_side
from collres_ros.core.config import SolverSettings
from collres_ros.core.contact_cache import ContactCache
from collres_ros.core.detection import Detection
from collres_ros.core.shapes import mass_properties
from collres_ros.core.types import (BodySpec, BodyStates, ContactKind, ContactReport,
                                    ContactSet, ContactState, Rejection, StepResult)

POSITION_ITERATIONS = 4   # split-impulse iterations when some contact needs a push-out
BALANCED_FRICTION = 1e-3  # net friction / net normal impulse of a pair below which it rests
#                           (the solver converges to ~1e-4 relative: residual, not friction)
# extra iterations (times velocity_iterations) when all resting contacts are new
# (nothing to warm start from, e.g. a stack at its first step); scaled by their share
COLD_EXTRA = 1.0


class Detector(Protocol):
    """What the world needs from detection (``Detection`` is the real one)."""

    settings: SolverSettings

    def detect(self, previous: BodyStates, current: BodyStates,
               active: np.ndarray | None = None) -> ContactSet: ...


class World:
    """A fixed list of bodies, their materials, the solver settings and the warm-start cache."""

    def __init__(self, bodies: Sequence[BodySpec], settings: SolverSettings,
                 detector: Detector | None = None) -> None:
        """``detector`` replaces coal detection (tests feed hand-made ContactSets)."""
        self.specs = list(bodies)
        self._settings = settings
        self._collision = detector if detector is not None else \
            Detection(self.specs, settings)
        props = [mass_properties(spec) for spec in self.specs]
        self.inv_mass = np.array([p[0] for p in props], dtype=float)           # (N,) 1/kg
        self.inv_inertia_body = np.array([p[1] for p in props]).reshape(-1, 3, 3)
        self.dynamic = np.array([not s.static for s in self.specs]) & (self.inv_mass > 0.0)
        self.restitution = np.array([s.restitution for s in self.specs], dtype=float)
        self.static_friction = np.array([s.static_friction for s in self.specs], dtype=float)
        self.kinetic_friction = np.array([s.kinetic_friction for s in self.specs], dtype=float)
        self._cache = ContactCache()
        self._last_dt = 0.0
        # last step: detection and solve time (s), velocity sweeps done
        self.timing: dict[str, float] = {'detect': 0.0, 'solve': 0.0, 'iterations': 0}

    @property
    def settings(self) -> SolverSettings:
        return self._settings

    @settings.setter
    def settings(self, settings: SolverSettings) -> None:
        """New settings take effect at the next step."""
        self._settings = settings
        self._collision.settings = settings

    def set_material(self, index: int, restitution: float | None = None,
                     static_friction: float | None = None,
                     kinetic_friction: float | None = None) -> None:
        """Change one body's coefficients (taken as valid: the caller checks ranges)."""
        if restitution is not None:
            self.restitution[index] = restitution
        if static_friction is not None:
            self.static_friction[index] = static_friction
        if kinetic_friction is not None:
            self.kinetic_friction[index] = kinetic_friction

    def forget(self, bodies: np.ndarray) -> None:
        """Drop the warm-start impulses of these body indices (e.g. after a reset)."""
        self._cache.forget(np.asarray(bodies, np.int64))

    def step(self, previous: BodyStates, current: BodyStates, dt: float,
             active: np.ndarray | None = None) -> StepResult:
        """Resolve the contacts of the step previous -> current (dt > 0, s).

        ``previous``/``current``: all N bodies, world frame, before resolution
        (validated by the caller). ``active`` (N,) bool, False = quarantined:
        held at ``current`` with zero twist and infinite mass this step, its
        output state is ``current`` unchanged. Returns corrected states of all
        bodies, the solved contacts and non-finite results that were refused.
        A step longer than ``settings.max_dt`` is not warm started.
        """
        s = self._settings
        n = current.count
        active = np.ones(n, bool) if active is None else np.asarray(active, bool)
        movable = self.dynamic & active
        previous = _hold(previous, current, ~active)
        fresh = dt > s.max_dt
        started = time.perf_counter()
        # broad phase, narrow phase and time of impact (swept bounds, coal GJK/EPA, bisection)
        contacts = _finite(self._collision.detect(previous, current, active))
        detected = time.perf_counter()
        if contacts.count == 0:
            self.timing = {'detect': detected - started, 'solve': 0.0, 'iterations': 0}
            self._cache.clear()
            return StepResult(current.copy(), ContactReport.empty(), [])
        # manifolds: reference time of each contact and body, pre-solve velocities
        inv_mass = self.inv_mass * movable
        inv_inertia = rotation.world_inverse_inertia(
            current.orientation, self.inv_inertia_body) * movable[:, None, None]
        frame = _Frame(previous, current, contacts, dt, movable, ~active,
                       s.restitution_threshold)
        # prepare: constraint rows, coloured batches, combined materials
        restitution, friction = self._materials(contacts.body_a, contacts.body_b)
        rows = solver.prepare(frame.pair, contacts.normal, frame.r_a, frame.r_b, inv_mass,
                              inv_inertia, frame.velocity, frame.allowance, restitution,
                              friction, s.restitution_threshold, s.sticking_speed,
                              frame.sticking_velocity)
        # warm start from last step's impulses of the same pair and feature
        impulses = solver.Impulses.zeros(rows.count)
        cold = self._warm(rows, impulses, contacts, dt, s.warm_start and not fresh)
        velocity = frame.velocity.copy()
        solver.warm_start(rows, impulses, velocity)
        # iterate: sequential impulses over the colours (more while resting contacts are new)
        iterations = int(round(s.velocity_iterations * (1.0 + COLD_EXTRA * cold)))
        sweeps = solver.solve_velocities(rows, impulses, velocity, iterations)
        # restitution from the pre-solve approach speed, above the threshold only
        solver.apply_restitution(rows, impulses, velocity)
        # store impulses for next step's warm start (without the restitution part)
        friction = solver.friction_world(rows, impulses)
        back = np.argsort(rows.order)
        self._cache.store(contacts.body_a, contacts.body_b, contacts.feature,
                          impulses.normal[back], friction[back], contacts.point)
        self._last_dt = dt
        # correct poses: rewind/advance, then split-impulse push-out without velocity
        states = frame.advance(velocity, movable)
        push = frame.push_out(rows, velocity, s)
        pseudo = solver.solve_positions(rows, push, n, POSITION_ITERATIONS)
        states = _displace(states, pseudo, dt, frame.touched)
        # report: impulses, states, and the final guard against non-finite output
        normal_impulse = impulses.normal + impulses.restitution.mean(axis=1)
        state = solver.contact_states(rows, impulses, velocity, s.sticking_speed)
        state = _resting_when_friction_balances(frame.reported, state[back], friction[back],
                                                normal_impulse[back])
        report = ContactReport(frame.reported, normal_impulse[back], friction[back], state)
        rejected = self._guard(states, current)
        self.timing = {'detect': detected - started, 'solve': time.perf_counter() - detected,
                       'iterations': sweeps}
        return StepResult(states, report, rejected)

    def _materials(self, a: np.ndarray, b: np.ndarray
                   ) -> tuple[tuple[np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]]:
        """((e on A, e on B), (mu_static, mu_kinetic)) per contact, by the settings' rules.

        The kinetic coefficient never exceeds the static one of the same contact.
        """
        s = self._settings
        restitution = restitution_per_side(self.restitution[a], self.restitution[b],
                                           s.restitution_rule)
        mu_s = combine_friction(self.static_friction[a], self.static_friction[b],
                                s.friction_rule)
        mu_k = combine_friction(self.kinetic_friction[a], self.kinetic_friction[b],
                                s.friction_rule)
        return restitution, (mu_s, np.minimum(mu_s, mu_k))

    def _warm(self, rows: solver.ContactRows, impulses: solver.Impulses,
              contacts: ContactSet, dt: float, enabled: bool) -> float:
        """Fill ``impulses`` with the cached ones, scaled to this dt, inside the cone.

        Returns the fraction of persistent contacts that found no cached impulse.
        """
        persistent = contacts.kind[rows.order] == ContactKind.PERSISTENT
        if not enabled:
            return 1.0 if persistent.any() else 0.0
        normal, friction, found = self._cache.lookup(contacts.body_a, contacts.body_b,
                                                     contacts.feature, contacts.point)
        scale = dt / self._last_dt if self._last_dt > 0.0 else 0.0
        impulses.normal[:] = normal[rows.order] * scale
        tangent = solver.project_friction(rows, friction[rows.order] * scale)
        size = np.hypot(tangent[:, 0], tangent[:, 1])
        limit = rows.mu * impulses.normal
        over = size > limit
        tangent[over] *= (limit[over] / size[over])[:, None]
        impulses.tangent[:] = tangent
        cold = persistent & ~found[rows.order]
        return float(cold.sum()) / max(1, int(persistent.sum()))

    def _guard(self, states: BodyStates, current: BodyStates) -> list[Rejection]:
        """Bodies with a non-finite result keep their current input state; report them."""
        bad = ~(np.isfinite(states.position).all(1) & np.isfinite(states.orientation).all(1)
                & np.isfinite(states.linear).all(1) & np.isfinite(states.angular).all(1))
        rejected = []
        for i in np.flatnonzero(bad):
            states.position[i], states.orientation[i] = current.position[i], current.orientation[i]
            states.linear[i], states.angular[i] = current.linear[i], current.angular[i]
            rejected.append(Rejection(self.specs[i].name, 'non_finite_result',
                                      'the solver produced a non-finite state; input kept'))
        return rejected


class _Frame:
    """Reference configuration of the contacts and bodies of one step."""

    def __init__(self, previous: BodyStates, current: BodyStates, contacts: ContactSet,
                 dt: float, movable: np.ndarray, held: np.ndarray, threshold: float) -> None:
        """Held (inactive) bodies are fixed this step: zero twist, infinite mass."""
        self.previous, self.current, self.dt = previous, current, dt
        a, b = contacts.body_a, contacts.body_b
        self.pair = np.stack((a, b), axis=1)
        impact = contacts.kind != ContactKind.PERSISTENT
        # contact points are at the time of impact (IMPACT/TUNNELLED) or at the current state
        at = np.where(impact, contacts.toi, 1.0)[:, None]
        x0, x1 = previous.position, current.position
        self.r_a = contacts.point - (x0[a] + at * (x1[a] - x0[a]))
        self.r_b = contacts.point - (x0[b] + at * (x1[b] - x0[b]))
        v_now = _twist(current, held)
        # gap at the previous state of persistent contacts, from the current approach speed
        v_in = _point_velocity(v_now, self.pair, self.r_a, self.r_b, contacts.normal)
        gap = contacts.separation - v_in * dt
        closing = ~impact & (gap > 0.0) & (contacts.separation < 0.0) & (v_in < -threshold)
        toi = np.where(impact, contacts.toi, 0.0)
        toi = np.where(closing, gap / np.maximum(gap - contacts.separation, 1e-300), toi)
        impact |= closing
        self.reported = ContactSet(a, b, contacts.point, contacts.normal, contacts.separation,
                                   np.clip(toi, 0.0, 1.0), np.where(
                                       closing, ContactKind.IMPACT, contacts.kind).astype(np.int8),
                                   contacts.feature)
        # each movable body's reference fraction: its earliest time of impact, else 0
        n = current.count
        first = np.ones(n)
        np.minimum.at(first, np.concatenate((a[impact], b[impact])),
                      np.concatenate((toi[impact], toi[impact])))
        self.touched = np.zeros(n, bool)
        self.touched[a] = self.touched[b] = True
        self.touched &= movable
        self.impacted = np.zeros(n, bool)
        self.impacted[a[impact]] = self.impacted[b[impact]] = True
        self.impacted &= movable
        self.fraction = np.where(self.impacted, np.clip(first, 0.0, 1.0), 0.0)
        # pre-solve velocities: at the time of impact for impacted bodies (the twist of
        # a state is the velocity over the step that led to it, at mid-step), else current
        v_then = _twist(previous, held)
        self.external = v_now - v_then          # this step's external velocity change
        f = self.fraction[:, None]
        self.velocity = np.where(self.impacted[:, None], v_now + (f - 0.5) * self.external,
                                 v_now)
        self.sticking_velocity = v_then         # before this step's forces
        # speculative allowance: gap at the later of the two bodies' reference times
        later = np.maximum(self.fraction[a], self.fraction[b])
        remaining = np.maximum((1.0 - later) * dt, 1e-9 * dt)
        self.gap = np.where(impact, 0.0, gap + v_in * later * dt)
        self.remaining = np.where(impact, (1.0 - toi) * dt, remaining)
        self.allowance = np.maximum(self.gap, 0.0) / remaining

    def advance(self, velocity: np.ndarray, movable: np.ndarray) -> BodyStates:
        """Corrected states before push-out (see the module docstring)."""
        prev, cur, dt = self.previous, self.current, self.dt
        out = cur.copy()
        hit = self.impacted
        rest = self.touched & ~hit
        # persistent contact only: previous pose advanced by the new velocity for dt
        out.linear[rest], out.angular[rest] = velocity[rest, :3], velocity[rest, 3:]
        out.position[rest] = prev.position[rest] + velocity[rest, :3] * dt
        out.orientation[rest] = rotation.integrate(prev.orientation[rest], velocity[rest, 3:], dt)
        # impact: rewind to the time of impact, advance for the rest of the step
        f = self.fraction[hit][:, None]
        end = velocity[hit] + (0.5 - f) * self.external[hit]      # mid-step twist, as input
        mean = velocity[hit] + 0.5 * (1.0 - f) * self.external[hit]
        tau = (1.0 - f) * dt
        out.linear[hit], out.angular[hit] = end[:, :3], end[:, 3:]
        start = prev.position[hit] + f * (cur.position[hit] - prev.position[hit])
        out.position[hit] = start + mean[:, :3] * tau
        turned = rotation.slerp(prev.orientation[hit], cur.orientation[hit], f[:, 0])
        out.orientation[hit] = rotation.integrate(turned, mean[:, 3:], tau[:, 0])
        return out

    def push_out(self, rows: solver.ContactRows, velocity: np.ndarray,
                 s: SolverSettings) -> np.ndarray:
        """Pseudo normal speed (M,) m/s, colour order, that removes part of the predicted overlap.

        Predicted gap at the end of the step = reference gap + new normal speed
        times the remaining time; beyond ``linear_slop`` a fraction
        ``position_correction`` of it (at most ``max_correction``) is removed.
        """
        speed = np.einsum('mj,mj->m', rows.jacobian[:, 0, :], velocity[rows.pair].reshape(-1, 12))
        predicted = self.gap[rows.order] + speed * self.remaining[rows.order]
        depth = np.minimum(s.position_correction * np.maximum(-predicted - s.linear_slop, 0.0),
                           s.max_correction)
        return depth / self.dt


def _twist(states: BodyStates, held: np.ndarray) -> np.ndarray:
    """(N, 6) linear and angular velocity; held bodies and non-finite entries read as 0."""
    twist = np.concatenate((states.linear, states.angular), axis=1)
    return np.where(np.isfinite(twist) & ~held[:, None], twist, 0.0)


def _point_velocity(twist: np.ndarray, pair: np.ndarray, r_a: np.ndarray, r_b: np.ndarray,
                    normal: np.ndarray) -> np.ndarray:
    """Relative normal velocity (M,) m/s of B's point against A's (< 0 approaching)."""
    va = twist[pair[:, 0], :3] + np.cross(twist[pair[:, 0], 3:], r_a)
    vb = twist[pair[:, 1], :3] + np.cross(twist[pair[:, 1], 3:], r_b)
    return np.einsum('mi,mi->m', vb - va, normal)


def _hold(previous: BodyStates, current: BodyStates, held: np.ndarray) -> BodyStates:
    """Previous states with the held (inactive) bodies set to their current state."""
    if not held.any():
        return previous
    out = previous.copy()
    out.position[held], out.orientation[held] = current.position[held], current.orientation[held]
    out.linear[held], out.angular[held] = current.linear[held], current.angular[held]
    return out


def _finite(contacts: ContactSet) -> ContactSet:
    """Only the contacts whose numbers are all finite and whose normal is not zero."""
    norm = np.linalg.norm(contacts.normal, axis=1) if contacts.count else np.zeros(0)
    ok = (np.isfinite(contacts.point).all(1) & np.isfinite(norm) & (norm > 0.5)
          & np.isfinite(contacts.separation) & np.isfinite(contacts.toi))
    if ok.all():
        normal = contacts.normal / norm[:, None] if contacts.count else contacts.normal
        return ContactSet(contacts.body_a, contacts.body_b, contacts.point, normal,
                          contacts.separation, contacts.toi, contacts.kind, contacts.feature)
    return ContactSet(contacts.body_a[ok], contacts.body_b[ok], contacts.point[ok],
                      contacts.normal[ok] / norm[ok, None], contacts.separation[ok],
                      contacts.toi[ok], contacts.kind[ok], contacts.feature[ok])


def _displace(states: BodyStates, pseudo: np.ndarray, dt: float,
              touched: np.ndarray) -> BodyStates:
    """Poses moved by the split-impulse pseudo velocity for dt (velocities untouched)."""
    move = touched & np.any(pseudo != 0.0, axis=1)
    if move.any():
        states.position[move] += pseudo[move, :3] * dt
        states.orientation[move] = rotation.integrate(states.orientation[move],
                                                      pseudo[move, 3:], dt)
    return states


def _resting_when_friction_balances(contacts: ContactSet, state: np.ndarray,
                                    friction: np.ndarray, normal: np.ndarray) -> np.ndarray:
    """STICKING -> RESTING where a pair's friction impulses sum to nothing.

    A box at rest on a flat floor may carry equal and opposite friction
    impulses at its corners (a statically indeterminate manifold); no net
    friction holds it, so users read it as RESTING. Caller order, (M,) uint8.
    """
    sticking = state == ContactState.STICKING
    if not sticking.any():
        return state
    _, pair = np.unique(np.stack((contacts.body_a, contacts.body_b), axis=1), axis=0,
                        return_inverse=True)
    pair = pair.reshape(-1)
    net_friction = np.zeros((pair.max() + 1, 3))
    np.add.at(net_friction, pair, friction)
    net_normal = np.bincount(pair, weights=normal)
    balanced = np.linalg.norm(net_friction, axis=1) <= BALANCED_FRICTION * net_normal + 1e-15
    out = state.copy()
    out[sticking & balanced[pair]] = ContactState.RESTING
    return out
