"""Substeps: a long step resolved as several short ones (``World.step``).

A resting contact's load grows with the step (g dt per step), and the sequential-impulse
sweeps of a deep stack do not converge it at low rates: at 30 Hz a column of 7 cubes of
0.1 m topples within 1-2 s, and a pile of 1000 bodies never comes to rest (bodies 1-7 cm
into each other, the bottom boxes 12-16 mm into the floor), where at 120 Hz the same
pile sleeps after 3 s, 0.3 mm deep (bench/bench_rest.py). With ``settings.max_substep``
> 0, a longer step is resolved as S = ceil(dt / max_substep) substeps of dt / S, as Box2D
v3 divides its step (there: 4 substeps of soft contacts with a relax sweep; here each
substep is a whole step of detection and solve). Off by default (0): on, the laws at 10
Hz and of single hand-made long steps change (README, "Substeps").

Substep s (1..S) goes from the answer of substep s - 1 (the previous state for s = 1)
to that answer advanced as the source integrates (semi-implicit Euler, ``advanced``): its
twist plus the step's external twist change / S (gravity g dt / S), its pose moved by
that twist for dt / S: each substep is a step of a source at S times the rate. A body
that no substep changed (flying free, asleep, held) ends the step at ``current``, bit
for bit; fixed bodies the caller drives follow ``along`` (poses and twists interpolated
between previous and current).

The step's contact report (``merge``) holds, for each pair of bodies (and pieces), its
contacts of the last substep that found it; their impulses are the sums over the
substeps (a contact of an earlier substep adds to the one of the same feature, else to
its pair's first), so impulse / dt is still the step's mean force (contact wrench), and
a contact that took part in an impact in any substep is reported IMPACT, its time of
impact a fraction of the whole step.
"""

from __future__ import annotations

import math

import numpy as np

from collres_ros.core.rotation import integrate, slerp
from collres_ros.core.types import (BodyStates, ContactKind, ContactReport, ContactSet,
                                    ContactState)


def count(dt: float, max_substep: float) -> int:
    """Substeps of a step of dt s (1: no substeps; max_substep 0: off)."""
    if max_substep <= 0.0 or dt <= max_substep:
        return 1
    return max(1, math.ceil(dt / max_substep - 1e-9))


def along(previous: BodyStates, current: BodyStates, f: float) -> BodyStates:
    """The input at fraction f of the step, poses and twists interpolated (lerp, slerp;
    ``current`` itself at f = 1): where the caller drives a fixed body."""
    if f >= 1.0:
        return current
    return BodyStates(previous.position + f * (current.position - previous.position),
                      slerp(previous.orientation, current.orientation, f),
                      previous.linear + f * (current.linear - previous.linear),
                      previous.angular + f * (current.angular - previous.angular))


def advanced(goal: BodyStates, answer: BodyStates, bodies: np.ndarray, linear: np.ndarray,
             angular: np.ndarray, h: float) -> BodyStates:
    """``goal`` with ``bodies`` (N,) bool advanced from their ``answer`` as their source
    integrates (semi-implicit Euler): twist + the step's external change per substep
    (``linear`` (N, 3) m/s, ``angular`` (N, 3) rad/s), then the pose moved by that twist
    for h s."""
    out = goal.copy()
    out.linear[bodies] = answer.linear[bodies] + linear[bodies]
    out.angular[bodies] = answer.angular[bodies] + angular[bodies]
    out.position[bodies] = answer.position[bodies] + h * out.linear[bodies]
    out.orientation[bodies] = integrate(answer.orientation[bodies], out.angular[bodies], h)
    return out


def changed(answer: BodyStates, goal: BodyStates) -> np.ndarray:
    """(N,) bool: the bodies whose answer is not their input ``goal`` as it was."""
    return ~((answer.position == goal.position).all(1)
             & (answer.orientation == goal.orientation).all(1)
             & (answer.linear == goal.linear).all(1)
             & (answer.angular == goal.angular).all(1))


def merge(reports: list[ContactReport]) -> ContactReport:
    """One step's report from its substeps' reports, in substep order (module docstring)."""
    reports = [r for r in reports if r.contacts.count]
    if not reports:
        return ContactReport.empty()
    if len(reports) == 1:
        return reports[0]
    substeps = len(reports)
    c = [r.contacts for r in reports]
    sub = np.concatenate([np.full(x.count, k) for k, x in enumerate(c)])
    a = np.concatenate([x.body_a for x in c])
    b = np.concatenate([x.body_b for x in c])
    pa = np.concatenate([x.piece_a if x.piece_a is not None else np.zeros(x.count, np.int64)
                         for x in c])
    pb = np.concatenate([x.piece_b if x.piece_b is not None else np.zeros(x.count, np.int64)
                         for x in c])
    feature = np.concatenate([x.feature for x in c])
    pair = np.unique(np.stack((a, b, pa, pb), 1), axis=0, return_inverse=True)[1].ravel()
    last = np.full(pair.max() + 1, -1)
    np.maximum.at(last, pair, sub)
    keep = sub == last[pair]
    normal = np.concatenate([r.normal_impulse for r in reports])
    friction = np.concatenate([r.friction_impulse for r in reports])
    state = np.concatenate([r.state for r in reports])
    kind = np.concatenate([x.kind for x in c])
    # a time of impact as a fraction of the whole step (a persistent contact's is 0)
    toi = np.where(kind == ContactKind.PERSISTENT, 0.0,
                   np.concatenate([(k + x.toi) / substeps for k, x in enumerate(c)]))
    # each contact of an earlier substep adds to the kept one of its pair and feature, else
    # to its pair's first kept contact
    kept = np.flatnonzero(keep)
    first = np.full(last.size, -1)
    first[pair[kept[::-1]]] = kept[::-1]
    key = {(int(pair[i]), int(feature[i])): int(i) for i in kept}
    into = np.array([key.get((int(pair[i]), int(feature[i])), int(first[pair[i]]))
                     for i in np.flatnonzero(~keep)], np.int64)
    dropped = np.flatnonzero(~keep)
    if dropped.size:
        np.add.at(normal, into, normal[dropped])
        np.add.at(friction, into, friction[dropped])
        hit = state[dropped] == ContactState.IMPACT
        earlier = into[hit]
        state[earlier] = ContactState.IMPACT
        toi[earlier], kind[earlier] = toi[dropped[hit]], kind[dropped[hit]]
    kept_manifolds, offset = [], 0
    for k, x in enumerate(c):
        rows = keep[sub == k]
        for m in x.manifolds:
            if rows[m[2]]:
                kept_manifolds.append((m[0], m[1], offset, m[3]))
                offset += m[3]
    pieces = any(x.piece_a is not None for x in c)
    contacts = ContactSet(
        a[keep], b[keep], np.concatenate([x.point for x in c])[keep],
        np.concatenate([x.normal for x in c])[keep],
        np.concatenate([x.separation for x in c])[keep], toi[keep], kind[keep],
        feature[keep], np.array(kept_manifolds, np.int64).reshape(-1, 4),
        pa[keep] if pieces else None, pb[keep] if pieces else None)
    return ContactReport(contacts, normal[keep], friction[keep], state[keep])
