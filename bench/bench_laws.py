"""A black-box audit of the contact laws at the rates users run (30, 60, 120, 240 Hz).

    .venv/bin/python bench/bench_laws.py [--only NAME ...] [--list]

Each check drives the public ``World`` (hand-made contacts through a fixed detector, or
coal's through the gravity integrator that closes the loop as collres_sim does) at
default settings unless the law names one, and states the law it checks. Prints a table
law / case / figure / pass-fail (markdown) and exits 1 if any check failed. The tests in
test/core state each law at one or two rates and sizes; this runs the variants (rates 30,
60, 120 and 240 Hz, other sizes, masses, angles and seeds), minutes, not seconds.
"""

from __future__ import annotations

import argparse
import math
import os
import sys
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, '..'))
sys.path.insert(0, os.path.join(HERE, '..', 'test', 'core'))
sys.path.insert(0, HERE)

from collres_ros.core.config import SOLVER_TUNING, SolverSettings  # noqa: E402
from collres_ros.core.rotation import to_matrix  # noqa: E402
from collres_ros.core.types import BodySpec, ContactKind  # noqa: E402
from collres_ros.core.world import World  # noqa: E402

from contacts import box, contact_set, FixedContacts, sphere, states  # noqa: E402,I100
from integrator import Simulation  # noqa: E402
from pile import make_pile  # noqa: E402
from test_impact_laws import elastic_gas, GAS_SIDE  # noqa: E402
from test_mirror_friction import asymmetry, mirror_hit  # noqa: E402
from test_stacks import pyramid, stand  # noqa: E402

G = 9.81
ZERO_G = np.zeros(3)
RATES = (30.0, 60.0, 120.0, 240.0)
CHECKS = {}
ROWS: list[tuple[str, str, str, bool]] = []


def check(group: str):
    def register(fn):
        CHECKS[group] = fn
        return fn
    return register


def row(law: str, case: str, figure: str, ok: bool) -> None:
    ROWS.append((law, case, figure, bool(ok)))
    print(f'| {law} | {case} | {figure} | {"pass" if ok else "FAIL"} |', flush=True)


def kinetic(world: World, st) -> float:
    """Kinetic energy (J) of the dynamic bodies."""
    energy = 0.0
    for i in range(len(world.specs)):
        if not world.dynamic[i]:
            continue
        rot = to_matrix(st.orientation[i])
        inertia = rot @ np.linalg.pinv(world.inv_inertia_body[i]) @ rot.T
        energy += 0.5 / world.inv_mass[i] * st.linear[i] @ st.linear[i] \
            + 0.5 * st.angular[i] @ inertia @ st.angular[i]
    return float(energy)


def solved_at(before, after):
    out = after.copy()
    out.position, out.orientation = before.position, before.orientation
    return out


def plane(mu_s=0.5, mu_k=0.3, e=0.0, normal=(0.0, 0.0, 1.0), mu_r=0.0, mu_t=0.0):
    return BodySpec('floor', 'plane', (*normal, 0.0), static=True, restitution=e,
                    static_friction=mu_s, kinetic_friction=mu_k, rolling_resistance=mu_r,
                    torsional_friction=mu_t)


# ---------------------------------------------------------------- impacts, e = 1

@check('cradle')
def cradle() -> None:
    """A ball at v0 hits a row of touching balls (e = 1): energy within 1 %, the last
    ball leaves at >= 0.95 v0, the others <= 0.05 v0."""
    for touching in (3, 5):
        for rate in RATES:
            for v0, grav in ((1.0, False), (3.0, False), (1.0, True)):
                r = 0.05
                bodies = [sphere(f's{i}', r, 1.0, e=1.0) for i in range(touching + 1)]
                x = [-2 * r - 0.004] + [2 * r * i for i in range(touching)]
                z = r if grav else 0.0
                pos = [[xi, 0.0, z] for xi in x]
                lin = [[v0, 0.0, 0.0]] + [[0.0] * 3] * touching
                if grav:          # on a frictionless floor under gravity
                    bodies = [plane(0.0, 0.0, e=1.0)] + bodies
                    pos, lin = [[0, 0, 0]] + pos, [[0, 0, 0]] + lin
                sim = Simulation(bodies, states(pos, lin), rate,
                                 gravity=np.array([0, 0, -G]) if grav else ZERO_G)
                e0 = sim.energy()
                for _ in range(max(8, int(0.3 * rate))):
                    sim.step()
                v = sim.state.linear[1 if grav else 0:, 0]
                ratio = sim.energy() / e0
                ok = abs(ratio - 1) <= 0.01 and v[-1] >= 0.95 * v0 and \
                    np.all(np.abs(v[:-1]) <= 0.05 * v0)
                row('cradle', f'{touching} touching, {rate:g} Hz, v0 {v0:g}'
                    + (', on a floor, g' if grav else ''),
                    f'E {ratio:.4f}, last {v[-1] / v0:.3f} v0, others <= '
                    f'{np.abs(v[:-1]).max() / v0:.3f} v0', ok)


def newton(normals, masses, centre_mass, u, e=1.0):
    """Simultaneous Newton impulses (N s) of strikers k on a centre ball: A P = -(1+e) u."""
    k = len(normals)
    a = np.array([[(1.0 / masses[i] if i == j else 0.0)
                   + normals[i] @ normals[j] / centre_mass for j in range(k)]
                  for i in range(k)])
    return np.linalg.solve(a, -(1 + e) * np.asarray(u))


@check('three_ball')
def three_ball() -> None:
    """Strikers hit a centre ball at rest at the same instant (e = 1): the simultaneous
    Newton answer within 1e-6 (each contact reverses its normal approach), the kinetic
    energy kept, mirror-symmetric when the hit is."""
    r = 0.1
    cases = [(120, (2.0, 2.0), (1.0, 1.0, 1.0), 0.01), (120, (2.0, 2.0), (1.0, 1.0, 1.0), 1 / 30),
             (90, (2.0, 2.0), (1.0, 1.0, 1.0), 0.01), (150, (2.0, 2.0), (1.0, 1.0, 1.0), 0.01),
             (180, (2.0, 2.0), (1.0, 1.0, 1.0), 0.01), (120, (2.0, 1.0), (1.0, 1.0, 1.0), 0.01),
             (120, (2.0, 2.0), (1.0, 3.0, 3.0), 0.01), (120, (2.0, 2.0), (5.0, 1.0, 1.0), 0.01),
             (100, (1.0, 3.0), (2.0, 1.0, 0.5), 0.01)]
    for angle, speeds, masses, dt in cases:
        th = math.radians(angle)
        n = [np.array([1.0, 0.0, 0.0]), np.array([math.cos(th), math.sin(th), 0.0])]
        bodies = [sphere(f'b{i}', r, masses[i], e=1.0) for i in range(3)]
        before = states([[0, 0, 0], 2 * r * n[0], 2 * r * n[1]],
                        [[0, 0, 0], -speeds[0] * n[0], -speeds[1] * n[1]])
        contacts = contact_set([0, 0], [1, 2], [r * n[0], r * n[1]], n, 0.0,
                               kind=ContactKind.IMPACT)
        world = World(bodies, SolverSettings(), FixedContacts(contacts))
        result = world.step(before, before.copy(), dt)
        law = newton(n, masses[1:], masses[0], [-speeds[0], -speeds[1]])
        got = result.report.normal_impulse
        k0, k1 = kinetic(world, before), kinetic(world, solved_at(before, result.states))
        ok = np.allclose(got, law, atol=1e-6) and abs(k1 / k0 - 1) < 1e-9
        if speeds[0] == speeds[1] and masses[1] == masses[2]:
            half = th / 2          # mirror about the bisector
            m = np.array([[math.cos(2 * half), math.sin(2 * half), 0],
                          [math.sin(2 * half), -math.cos(2 * half), 0], [0, 0, 1]])
            v = result.states.linear
            ok = ok and np.allclose(m @ v[1], v[2], atol=1e-9)
        row('simultaneous Newton', f'{angle} deg, v {speeds}, m {masses}, dt {dt:.4g}',
            f'P {np.round(got, 6)} law {np.round(law, 6)}, E {k1 / k0:.9f}', ok)


@check('gas')
def gas() -> None:
    """40 frictionless spheres (e = 1) in a closed box, no gravity, 5 s: energy within 1 %,
    never above +0.5 % (the default threshold, and 0.05 m/s)."""
    default = SolverSettings().restitution_threshold
    for rate, threshold in [(rate, threshold) for threshold in (default, 0.05)
                            for rate in RATES]:
        sim = elastic_gas(rate, threshold)
        e0, ratios = sim.energy(), []
        for _ in range(int(5 * rate)):
            sim.step()
            ratios.append(sim.energy() / e0)
        inside = np.abs(sim.state.position[6:]).max() < GAS_SIDE / 2
        ok = min(ratios) >= 0.99 and max(ratios) <= 1.005 and inside
        row('elastic gas', f'{rate:g} Hz, threshold {threshold}',
            f'E min {min(ratios):.4f} max {max(ratios):.4f} end {ratios[-1]:.4f}'
            + ('' if inside else ', a ball left the box'), ok)


@check('gas_sweep')
def gas_sweep() -> None:
    """The elastic gas (threshold 0.05 m/s) over ball radii (the box scaled with them),
    rms speeds and two seeds at 30-240 Hz: energy within 1 %, never above +0.5 %."""
    for radius in (0.005, 0.02, 0.05, 0.2):
        for rms in (0.5, 1.5, 5.0):
            for rate in (30.0, 50.0, 60.0, 100.0, 120.0, 240.0):
                low, high = 1.0, 1.0
                for seed in (1, 2):
                    sim = elastic_gas(rate, 0.05, radius, rms, seed)
                    e0 = sim.energy()
                    for _ in range(int(5 * rate)):
                        sim.step()
                        low = min(low, sim.energy() / e0)
                        high = max(high, sim.energy() / e0)
                row('elastic gas', f'r {radius} m, {rms} m/s rms, {rate:g} Hz, seeds 1-2',
                    f'E min {low:.4f} max {high:.4f}', low >= 0.99 and high <= 1.005)


def apexes(height):
    return [float(height[i]) for i in range(1, len(height) - 1)
            if height[i] >= height[i - 1] and height[i] > height[i + 1]]


@check('bounce')
def bounce() -> None:
    """A ball dropped from 1 m (e 0.8) bounces to e^2, e^4, e^6 (within 2 %)."""
    for rate in RATES:
        for r in (0.1, 0.02):
            e = 0.8
            sim = Simulation([plane(), sphere('ball', r, 1.0, e=e)],
                             states([[0, 0, 0], [0, 0, 1.0 + r]], np.zeros((2, 3))), rate)
            heights = apexes(sim.run(2.6).positions()[:, 1, 2] - r)[:3]
            law = [e ** 2, e ** 4, e ** 6]
            # a sampled apex is at most g (dt/2)^2 / 2 below the true one
            tol = [0.02 * w + G / (8 * rate * rate) for w in law]
            ok = len(heights) == 3 and all(abs(h - w) <= t for h, w, t in
                                           zip(heights, law, tol))
            row('e^2 bounces', f'{rate:g} Hz, r {r}', f'apexes {np.round(heights, 4)} '
                f'law {np.round(law, 4)}', ok)


@check('exchange')
def exchange() -> None:
    """Head-on equal spheres (e = 1) swap velocities; a cue ball hitting an equal ball at
    rest off-centre (frictionless, e = 1) leaves at 90 deg to it, momentum and energy kept."""
    for rate in RATES:
        world_bodies = [sphere('a', 0.1, 1.0, e=1.0), sphere('b', 0.1, 1.0, e=1.0)]
        sim = Simulation(world_bodies, states([[-0.3, 0, 0], [0.3, 0, 0]],
                                              [[2.0, 0, 0], [-1.0, 0, 0]]), rate,
                         gravity=ZERO_G)
        sim.run(0.5)
        v = sim.state.linear[:, 0]
        row('two-ball exchange', f'{rate:g} Hz, 2 and -1 m/s', f'v {np.round(v, 9)}',
            abs(v[0] + 1.0) < 1e-6 and abs(v[1] - 2.0) < 1e-6)
        sim = Simulation(world_bodies, states([[-0.3, 0.1, 0], [0.3, 0, 0]],
                                              [[2.0, 0, 0], [0, 0, 0]]), rate,
                         gravity=ZERO_G)
        e0 = sim.energy()
        sim.run(0.5)
        v = sim.state.linear
        p = v.sum(axis=0)
        cos = v[0] @ v[1] / max(1e-12, np.linalg.norm(v[0]) * np.linalg.norm(v[1]))
        ok = np.allclose(p, [2.0, 0, 0], atol=1e-9) and abs(sim.energy() / e0 - 1) < 1e-6 \
            and abs(cos) < 1e-6 and np.linalg.norm(v[1]) > 0.1
        row('billiards', f'{rate:g} Hz, b = r/2', f'p {np.round(p, 9)}, E '
            f'{sim.energy() / e0:.9f}, cos {cos:.1e}', ok)


# ---------------------------------------------------------------- manifolds

@check('mirror')
def mirror() -> None:
    """Mirror-symmetric hits give mirror-symmetric impulses and no energy gain."""
    for spin, dt, e, mu in ((60.0, 0.01, 0.5, 0.5), (300.0, 0.01, 0.5, 0.5),
                            (60.0, 1 / 30, 0.5, 0.5), (60.0, 0.01, 1.0, 0.0),
                            (60.0, 0.01, 0.0, 1.0)):
        bodies = [box('wall', (0.2, 4.0, 4.0), 1.0, e=e, mu_s=mu, mu_k=0.8 * mu, static=True),
                  box('stick', (0.1, 1.0, 0.1), 2.0, e=e, mu_s=mu, mu_k=0.8 * mu)]
        before = states([[-0.1, 0.0, 0.0], [0.05, 0.0, 0.0]], [[0, 0, 0], [-3.0, 0.0, 1.0]],
                        [[0, 0, 0], [0.0, spin, 0.0]])
        corners = [[0.0, 0.5, -0.05], [0.0, -0.5, -0.05]]
        contacts = contact_set(0, 1, corners, [1.0, 0.0, 0.0], 0.0, kind=ContactKind.IMPACT)
        world = World(bodies, SolverSettings(), FixedContacts(contacts))
        result = world.step(before, before.copy(), dt)
        p = result.report.normal_impulse
        f = result.report.friction_impulse
        w = result.states.angular[1]
        k0, k1 = kinetic(world, before), kinetic(world, solved_at(before, result.states))
        ok = p[0] > 0 and abs(p[0] - p[1]) <= 1e-6 * p[0] and \
            np.allclose(f[0], [1, -1, 1] * f[1], atol=1e-6 * p[0]) and \
            abs(w[0]) < 1e-6 and abs(w[2]) < 1e-6 and k1 <= k0 * (1 + 1e-9)
        row('mirror impulses', f'stick, spin {spin:g}, dt {dt:.3g}, e {e}, mu {mu}',
            f'P {np.round(p, 6)}, w_x {w[0]:.1e}, E {k1 / k0:.6f}', ok)
    # a cube hitting a floor flat on its four corners, spinning about x: mirror x -> -x
    for dt, e, mu in ((0.01, 0.5, 0.5), (1 / 30, 0.8, 1.0), (0.01, 1.0, 0.0)):
        h = 0.1
        bodies = [box('floor', (4, 4, 0.2), 1.0, e=e, mu_s=mu, mu_k=0.8 * mu, static=True),
                  box('cube', (2 * h,) * 3, 1.0, e=e, mu_s=mu, mu_k=0.8 * mu)]
        before = states([[0, 0, -0.1], [0, 0, h]], [[0, 0, 0], [0, 0.5, -3.0]],
                        [[0, 0, 0], [5.0, 0, 0]])
        pts = [[x, y, 0.0] for x in (-h, h) for y in (-h, h)]
        contacts = contact_set(0, 1, pts, [0, 0, 1.0], 0.0, kind=ContactKind.IMPACT)
        world = World(bodies, SolverSettings(), FixedContacts(contacts))
        result = world.step(before, before.copy(), dt)
        p = result.report.normal_impulse
        w = result.states.angular[1]
        k0, k1 = kinetic(world, before), kinetic(world, solved_at(before, result.states))
        ok = np.allclose(p[:2], p[2:], atol=1e-6 * p.max()) and abs(w[1]) < 1e-6 and \
            abs(w[2]) < 1e-6 and k1 <= k0 * (1 + 1e-9) and p.sum() > 0
        row('mirror impulses', f'cube flat on 4 corners, spin x, dt {dt:.3g}, e {e}, mu {mu}',
            f'P {np.round(p, 5)}, w {np.round(w, 6)}, E {k1 / k0:.6f}', ok)

    # random mirror hits (test_mirror_friction's, which runs the first class): the hits
    # above slide at the cone limit through the whole impact, where the order in which a
    # manifold's points are swept does not matter; these stick, start or stop sliding
    rng = np.random.default_rng(14)
    for fixed in (False, True):
        for pairs in (1, 2):
            errors = [asymmetry(*mirror_hit(rng, fixed, pairs)) for _ in range(500)]
            bad = sum(e > 1e-6 for e in errors)
            row('mirror impulses', f'500 random hits, {2 * pairs} points, '
                + ('fixed wall' if fixed else 'dynamic pair'),
                f'{bad} asymmetric, worst {max(errors):.1e}', bad == 0)


@check('iterations')
def iterations() -> None:
    """More velocity iterations converge: boxes overlapping a floor and each other (e = 0,
    coal's contacts, one World.step): no energy gain at any count, and the answer at 300
    and 1000 iterations closer together than at 10 and 30."""
    rng = np.random.default_rng(5)
    for case in range(6):
        bodies = [plane(0.6, 0.5)] + [box(f'b{i}', rng.uniform(0.1, 0.4, 3), 1.0 + 4 * i,
                                          e=0.0, mu_s=0.6, mu_k=0.5) for i in range(2)]
        q = rng.normal(size=(2, 4))
        q /= np.linalg.norm(q, axis=1, keepdims=True)
        pos = [[0, 0, 0], [0, 0, 0.08], [rng.uniform(0.05, 0.2), 0.0, 0.2]]
        before = states(pos, np.r_[np.zeros((1, 3)), rng.normal(0, 1, (2, 3))],
                        np.r_[np.zeros((1, 3)), rng.normal(0, 3, (2, 3))],
                        np.r_[[[0, 0, 0, 1]], q])
        answers, gains = {}, {}
        for n in (10, 30, 100, 300, 1000):
            world = World(bodies, SolverSettings(velocity_iterations=n, sleeping=False))
            result = world.step(before, before.copy(), 1 / 60)
            answers[n] = np.r_[result.states.linear[1:].ravel(), result.states.angular[1:].ravel()]
            gains[n] = kinetic(world, solved_at(before, result.states)) / kinetic(world, before)
        early = np.abs(answers[30] - answers[10]).max()
        late = np.abs(answers[1000] - answers[300]).max()
        ok = max(gains.values()) <= 1 + 1e-9 and late <= max(early, 1e-9)
        row('iterations converge', f'two boxes in a floor, seed 5 case {case}',
            f'E/E0 {[round(g, 4) for g in gains.values()]}, |d| 10-30 {early:.2e}, '
            f'300-1000 {late:.2e}', ok)


# ---------------------------------------------------------------- rest

@check('hover')
def hover() -> None:
    """A box dropped on an edge or a corner rests on its four lowest corners, each within
    the slop (0.1 mm) of the floor."""
    from test_hovering import drop
    configs = [((1.0, 1.0, 0.1), (1, 1, 0), 42, 0.5), ((1.0, 1.0, 0.1), (0.3, 1, 0.2), 49, 0.5),
               ((0.2, 0.2, 0.2), (1, 0, 0), 40, 0.5), ((0.2, 0.2, 0.2), (1, 1, 1), 50, 0.5),
               ((0.4, 0.1, 0.05), (1, 0.3, 0), 30, 1.2), ((2.0, 2.0, 0.1), (1, 1, 0), 20, 0.5),
               ((0.05, 0.05, 0.05), (1, 1, 1), 50, 0.5)]
    for size, axis, angle, mu in configs:
        for rate in (30.0, 60.0, 240.0):
            support, speed = drop(size, axis, angle, rate, mu)
            ok = speed < 1e-3 and np.all(np.abs(support) <= 1e-4 + 1e-6)
            row('nothing hovers', f'{size} about {axis} {angle} deg, {rate:g} Hz, mu {mu}',
                f'corners {np.round(support * 1000, 3)} mm, speed {speed:.1e}', ok)


def cube(name, size, mass=1.0):
    return box(name, (size,) * 3, mass, mu_s=0.5, mu_k=0.3)


@check('towers')
def towers() -> None:
    """Towers of 20 equal cubes drift < 5 mm in 10 s whatever their size and the rate."""
    cases = [(s, r, 1.0) for s in (0.05, 0.2, 1.0) for r in RATES] + \
        [(0.02, 240.0, 1.0), (3.0, 240.0, 1.0), (0.2, 60.0, 50.0), (0.02, 60.0, 1.0),
         (3.0, 30.0, 1.0)]
    for size, rate, mass in cases:
        bodies = [plane()] + [cube(f'c{i}', size, mass) for i in range(20)]
        start = np.array([[0.0, 0.0, 0.0]] + [[0.0, 0.0, size * (i + 0.5)] for i in range(20)])
        moved, e0, highest = stand(bodies, start, rate=rate)
        row('tower of 20', f'{size} m, {rate:g} Hz, {mass:g} kg',
            f'drift {moved * 1000:.3f} mm, energy gain {highest - e0:.2e} J',
            moved < 0.005 and highest <= e0 + 1e-9 * abs(e0))


@check('towers_awake')
def towers_awake() -> None:
    """Towers of 20 cubes of the default material drift < 5 mm in 10 s with sleeping off
    (the solver's answer, not the sleepers': with sleeping on they fall asleep within
    0.6 s, before any sway grows)."""
    for size in (0.01, 0.02, 0.05, 0.1, 0.2, 1.0):
        for rate in RATES:
            bodies = [BodySpec('floor', 'plane', (0.0, 0.0, 1.0, 0.0), static=True)] + \
                [BodySpec(f'c{i}', 'box', (size,) * 3) for i in range(20)]
            start = np.array([[0.0, 0.0, 0.0]] + [[0.0, 0.0, size * (i + 0.5)]
                                                  for i in range(20)])
            sim = Simulation(bodies, states(start, np.zeros_like(start)), rate,
                             SolverSettings(sleeping=False))
            moved = 0.0
            for _ in range(int(round(10 * rate))):
                sim.step()
                moved = max(moved, float(np.linalg.norm(sim.state.position[1:] - start[1:],
                                                        axis=1).max()))
            row('tower of 20 awake', f'{size} m, {rate:g} Hz, default material',
                f'drift {moved * 1000:.3f} mm', moved < 0.005)


@check('stacks')
def stacks() -> None:
    """The 1000:1 stack moves < 0.1 mm in 10 s, the pyramid of 55 < 1 mm."""
    for rate in RATES:
        size = 0.2
        bodies = [plane(), cube('light', size, 1.0), cube('heavy', size, 1000.0)]
        start = np.array([[0.0, 0.0, 0.0], [0.0, 0.0, size / 2], [0.0, 0.0, 1.5 * size]])
        moved, e0, highest = stand(bodies, start, rate=rate)
        row('1000:1 stack', f'{rate:g} Hz', f'drift {moved * 1000:.4f} mm',
            moved < 1e-4 and highest <= e0 + 1e-9 * abs(e0))
    for rate in RATES:
        bodies, start = pyramid()
        moved, e0, highest = stand(bodies, start, rate=rate)
        row('pyramid of 55', f'{rate:g} Hz', f'drift {moved * 1000:.4f} mm',
            moved < 1e-3 and highest <= e0 + 1e-9 * abs(e0))


@check('column')
def column() -> None:
    """A column of 8 cubes of 0.1 m, 20 mm apart and 5 mm above the floor, each shifted
    sideways by up to 3 mm (20 layouts, seeded), dropped at rest: over its first second no
    two cubes overlap by more than 2 mm as they land on each other (each substep needs its
    sweeps while the loads build: later substeps with fewer sweeps than the first let
    them sink deeper)."""
    from collres_ros.core.detection import Detection
    size, gap, count = 0.1, 0.02, 8
    for rate in RATES:
        deepest = []
        for seed in range(20):
            rng = np.random.default_rng(seed)
            shift = rng.uniform(-0.003, 0.003, (count, 2))
            start = [[0.0, 0.0, 0.0]] + [[shift[k, 0], shift[k, 1],
                                          0.005 + size / 2 + (size + gap) * k]
                                         for k in range(count)]
            bodies = [plane(0.6, 0.4)] + [box(f'c{k}', (size,) * 3, 1.0, e=0.2, mu_s=0.6,
                                              mu_k=0.4) for k in range(count)]
            settings = SolverSettings(sleeping=False)
            sim = Simulation(bodies, states(start, np.zeros((count + 1, 3))), rate, settings)
            probe = Detection(sim.world.specs, settings)
            worst = 0.0
            for _ in range(int(round(rate))):
                sim.step()
                seen = probe.detect(sim.state, sim.state)
                cubes = seen.body_a > 0
                if cubes.any():
                    worst = max(worst, float(-seen.separation[cubes].min()))
            deepest.append(worst)
        deepest = np.array(deepest) * 1000
        row('a dropped column lands', f'8 cubes, {rate:g} Hz, 20 layouts',
            f'deepest overlap median {np.median(deepest):.2f} mm, max {deepest.max():.2f} mm',
            deepest.max() < 2.0)


@check('heavy_drop')
def heavy_drop() -> None:
    """A 1000 kg cube dropped 20 mm onto a 1 kg cube resting on the floor (offsets 0-40 mm)
    lands on it and stays on it: it never sinks into the light cube by more than 5 mm, the
    light cube is not driven into the floor, the two do not swap places."""
    size = 0.2
    for rate in RATES:
        for offset in (0.0, 0.002, 0.005, 0.01, 0.02, 0.04):
            bodies = [plane(), cube('light', size, 1.0), cube('heavy', size, 1000.0)]
            start = np.array([[0, 0, 0], [0, 0, size / 2], [offset, 0, 1.5 * size + 0.02]])
            sim = Simulation(bodies, states(start, np.zeros_like(start)), rate)
            deepest, closest = 0.0, np.inf
            for _ in range(int(3 * rate)):
                sim.step()
                deepest = max(deepest, size / 2 - sim.state.position[1, 2])
                closest = min(closest, sim.state.position[2, 2] - sim.state.position[1, 2])
            z = sim.state.position[:, 2]
            ok = closest > size - 0.005 and deepest < 0.005 and \
                abs(z[2] - 1.5 * size) < 0.002
            row('heavy on light drop', f'{rate:g} Hz, offset {offset * 1000:g} mm',
                f'heavy into light {max(size - closest, 0) * 1000:.1f} mm, light z {z[1]:.4f}, '
                f'heavy z {z[2]:.4f} (rest {1.5 * size:.2f}), light into floor '
                f'{deepest * 1000:.2f} mm', ok)


def bounces_to_rest(e, h, threshold):
    t0 = np.sqrt(2 * h / G)
    bounces = int(np.floor(np.log(threshold / (G * t0)) / np.log(e))) + 1
    return t0 * (1 + 2 * e * (1 - e ** bounces) / (1 - e))


@check('rest')
def rest() -> None:
    """A ball dropped from 0.3 m (e 0.8) comes to rest when the bounce law at its resting
    speed says (the threshold or resting_factor g dt, whichever is larger; within 8 steps)
    and then stays; any threshold, also below g dt."""
    factor = next(spec.default for spec in SOLVER_TUNING if spec.name == 'resting_factor')
    for rate in RATES:
        for threshold in (0.5, 1.1 * G / rate, 0.05):
            r, e, h = 0.1, 0.8, 0.3
            sim = Simulation([plane(e=0.0), sphere('ball', r, 1.0, e=e)],
                             states([[0, 0, 0], [0, 0, h + r]], np.zeros((2, 3))), rate,
                             SolverSettings(restitution_threshold=threshold))
            height = sim.run(4.0).positions()[:, 1, 2] - r
            above = np.flatnonzero(height > 1e-5)
            t = (above[-1] + 1) / rate
            law = bounces_to_rest(e, h, max(threshold, factor * G / rate))
            limit = np.sqrt(2 * h / G) * (1 + e) / (1 - e)
            ok = abs(t - law) <= 8 / rate and np.all(np.abs(height[above[-1] + 1:]) < 1e-5)
            row('rest that is rest', f'{rate:g} Hz, threshold {threshold:.3f}',
                f'rests {t:.3f} s, law {law:.3f} s, t0(1+e)/(1-e) {limit:.3f} s', ok)


# ---------------------------------------------------------------- rolling

@check('rolling')
def rolling() -> None:
    """A ball rolling on a floor decelerates at (5/7) mu_r g (3 %); it holds on a slope
    while tan <= mu_r and rolls above; spin about the normal decays at (5/2) mu_t g / r."""
    for rate in RATES:
        for r, mass, mu_r in ((0.1, 1.0, 0.05), (0.02, 0.1, 0.05), (0.5, 20.0, 0.1)):
            ball = BodySpec('ball', 'sphere', (r,), mass=mass, restitution=0.0,
                            static_friction=1.0, kinetic_friction=1.0, rolling_resistance=mu_r)
            v0 = 2.0
            sim = Simulation([plane(1.0, 1.0, mu_r=mu_r), ball],
                             states([[0, 0, 0], [0, 0, r]], [[0, 0, 0], [v0, 0, 0]],
                                    [[0, 0, 0], [0, v0 / r, 0]]), rate)
            speeds = []
            for _ in range(int(rate)):
                sim.step()
                speeds.append(sim.state.linear[1, 0])
            speeds = np.array(speeds)
            t = np.arange(1, len(speeds) + 1) / rate
            keep = np.flatnonzero(speeds > 0.05)[2:]
            slope = np.polyfit(t[keep], speeds[keep], 1)[0]
            law = 5 / 7 * mu_r * G
            slip = abs(sim.state.linear[1, 0] - sim.state.angular[1, 1] * r)
            row('rolling resistance', f'{rate:g} Hz, r {r}, m {mass}, mu_r {mu_r}',
                f'decel {-slope:.4f}, law {law:.4f}, slip {slip:.1e}',
                abs(-slope / law - 1) <= 0.03 and slip < 0.005 * v0)
        for mu_r in (0.1, 0.3):
            for factor in (0.9, 1.1):
                th = math.atan(factor * mu_r)
                normal = np.array([-math.sin(th), 0.0, math.cos(th)])
                r = 0.1
                slope_body = BodySpec('slope', 'plane', (*normal, 0.0), static=True,
                                      static_friction=2.0, kinetic_friction=2.0,
                                      rolling_resistance=mu_r)
                ball = BodySpec('ball', 'sphere', (r,), mass=1.0, static_friction=2.0,
                                kinetic_friction=2.0, rolling_resistance=mu_r)
                sim = Simulation([slope_body, ball], states([[0, 0, 0], r * normal],
                                                            np.zeros((2, 3))), rate)
                start = sim.state.position[1].copy()
                sim.run(1.0)
                went = np.linalg.norm(sim.state.position[1] - start)
                law = 0.5 * 5 / 7 * G * (math.sin(th) - mu_r * math.cos(th))
                if factor < 1:
                    ok = went < 1e-3
                    fig = f'moved {went * 1000:.3f} mm (holds)'
                else:
                    ok = abs(went / law - 1) <= 0.1
                    fig = f'rolled {went:.4f} m, law {law:.4f} m'
                row('slope holds iff tan <= mu_r', f'{rate:g} Hz, mu_r {mu_r}, tan = '
                    f'{factor} mu_r', fig, ok)
        for r, mu_t in ((0.1, 0.05), (0.03, 0.2)):
            ball = BodySpec('ball', 'sphere', (r,), mass=1.0, static_friction=1.0,
                            kinetic_friction=1.0, torsional_friction=mu_t)
            w0 = 10.0
            sim = Simulation([plane(1.0, 1.0, mu_t=mu_t), ball],
                             states([[0, 0, 0], [0, 0, r]], np.zeros((2, 3)),
                                    [[0, 0, 0], [0, 0, w0]]), rate)
            spins = []
            law = mu_t * r * G / (0.4 * r * r)
            for _ in range(max(8, int(rate * 1.2 * w0 / law))):
                sim.step()
                spins.append(sim.state.angular[1, 2])
            t = np.arange(1, len(spins) + 1) / rate
            spins = np.array(spins)
            keep = np.flatnonzero(spins > 0.1 * w0)    # while it spins, from the start
            slope = np.polyfit(np.r_[0.0, t[keep]], np.r_[w0, spins[keep]], 1)[0]
            row('torsional friction', f'{rate:g} Hz, r {r}, mu_t {mu_t}',
                f'decay {-slope:.3f} rad/s^2, law {law:.3f}, drift '
                f'{np.linalg.norm(sim.state.linear[1]):.1e} m/s',
                abs(-slope / law - 1) <= 0.03 and np.linalg.norm(sim.state.linear[1]) < 1e-6)


@check('pile_rest')
def pile_rest() -> None:
    """A dropped pile (make_pile: 100 bodies in a bin, defaults): 2 s after the drop every
    body is under 0.05 m/s at its farthest point (sleeping off, so the solver's answer is
    measured, not the sleepers')."""
    for kind in ('mixed', 'cubes'):
        for rate in RATES:
            for seed in (1, 2):
                bodies, initial = make_pile(100, seed=seed, kind=kind)
                sim = Simulation(bodies, initial, rate, SolverSettings(sleeping=False))
                reach = np.array([0.0 if b.static else (b.size[0] if b.shape == 'sphere'
                                                        else 0.5 * float(np.linalg.norm(b.size)))
                                  for b in bodies])
                for _ in range(int(2 * rate)):
                    sim.step()
                speed = np.linalg.norm(sim.state.linear, axis=1) + \
                    np.linalg.norm(sim.state.angular, axis=1) * reach
                row('settled pile rests in 2 s', f'{kind} 100, {rate:g} Hz, seed {seed}',
                    f'fastest point {speed.max():.4f} m/s ({bodies[int(speed.argmax())].name})',
                    speed.max() < 0.05)


HEAP_CASES = ((120.0, 3), (120.0, 4), (60.0, 3), (240.0, 3))


@check('heap')
def heap() -> None:
    """The heap law of test_heap (a pour of 100 spheres with rolling resistance 0.3 forms a
    heap steeper than 15 deg, and rests: the fastest sphere's median speed over a second
    under 0.05 m/s within 8 s of the last release, the angle measured then) at other rates
    and release jitter seeds."""
    import test_heap
    for rate, seed in HEAP_CASES:
        state, rested = test_heap.pour(0.3, seed, rate)
        angle = test_heap.angle_of_repose(state)[0]
        row('heap > 15 deg', f'{rate:g} Hz, jitter seed {seed}',
            f'{angle:.1f} deg, ' + (f'rests {rested:.2f} s after the last release'
                                    if rested is not None else 'does not rest within 8 s'),
            angle > 15.0 and rested is not None)


@check('warm')
def warm() -> None:
    """A box touching down whose state arrives twice 1 ns apart, then the next message
    later: it stays on the floor, does not spin up, gains no energy."""
    import test_warm_start as w
    from collres_ros.core.pipeline import Resolver
    for gap_ms in (1, 33, 100, 400, 600):
        for vx in (0.1, 1.0):
            resolver = Resolver.for_scene(w.floor_and_box())
            landing = w.box(w.HALF - 2e-4, (vx, 0.0, -0.3))
            resolver.resolve(w.T0, [landing])
            resolver.resolve(w.T0 + 1 * w.NS, [landing])
            out = resolver.resolve(w.T0 + 1 * w.NS + gap_ms * w.MS,
                                   [w.box(w.HALF - 2e-4, (vx, 0.0, 0.0))])
            lin, ang = out.states.linear[0], out.states.angular[0]
            ok = lin[2] < 1e-3 and np.linalg.norm(ang) < 1e-2 and \
                np.linalg.norm(lin) <= vx * (1 + 1e-9)
            row('warm start after a glitch', f'gap {gap_ms} ms, sliding {vx} m/s',
                f'v {np.round(lin, 4)}, |w| {np.linalg.norm(ang):.1e}', ok)


# ---------------------------------------------------------------- variants of the above

COMBINE = {'average': lambda a, b: (a + b) / 2, 'min': min, 'max': max,
           'multiply': lambda a, b: a * b}


@check('restitution_rules')
def restitution_rules() -> None:
    """A ball dropped from 1 m on a floor of another restitution bounces to e^2 with e the
    two combined by solver.restitution_rule (average, min, max, multiply; within 2 %)."""
    for rule, combined in COMBINE.items():
        for e_ball, e_floor in ((0.8, 0.5), (0.9, 0.0), (1.0, 0.6)):
            for rate in (60.0, 240.0):
                r = 0.05
                e = combined(e_ball, e_floor)
                sim = Simulation([plane(e=e_floor), sphere('ball', r, 1.0, e=e_ball)],
                                 states([[0, 0, 0], [0, 0, 1.0 + r]], np.zeros((2, 3))), rate,
                                 SolverSettings(restitution_rule=rule,
                                                restitution_threshold=0.05))
                heights = apexes(sim.run(1.6).positions()[:, 1, 2] - r)
                first = heights[0] if heights else 0.0
                law = e * e
                ok = abs(first - law) <= 0.02 * law + G / (8 * rate * rate) if law > 0 \
                    else first < 2e-3
                row('restitution rule', f'{rule}, ball {e_ball} on floor {e_floor}, '
                    f'{rate:g} Hz', f'apex {first:.4f} law {law:.4f}', ok)


@check('bounce_sizes')
def bounce_sizes() -> None:
    """A ball of 1 cm, 10 cm or 1 m dropped from 1 m: e 0.5 bounces to e^2, e^4 (2 %), e 1
    back to 1 m twice, e 0 stays on the floor."""
    for rate in RATES:
        for r in (0.01, 0.1, 1.0):
            for e in (0.0, 0.5, 1.0):
                sim = Simulation([plane(), sphere('ball', r, 1.0, e=e)],
                                 states([[0, 0, 0], [0, 0, 1.0 + r]], np.zeros((2, 3))), rate,
                                 SolverSettings(restitution_threshold=0.05))
                height = sim.run(2.6 if e < 1 else 3.0).positions()[:, 1, 2] - r
                if e == 0:
                    after = np.abs(height[int(0.6 * rate):]).max()
                    ok, figure = after < 1e-3, f'highest after landing {after:.1e} m'
                else:
                    got = apexes(height)[:2]
                    law = [e ** 2, e ** 4]
                    ok = len(got) == 2 and all(abs(h - w) <= 0.02 * w + G / (8 * rate * rate)
                                               for h, w in zip(got, law))
                    figure = f'apexes {np.round(got, 4)} law {np.round(law, 4)}'
                row('e^2 bounces', f'e {e}, r {r}, {rate:g} Hz', figure, ok)


@check('order')
def order() -> None:
    """Impacts do not depend on the order of the bodies or of the contacts: the symmetric
    three-ball hit in every order of its bodies, its two contacts either way round (the same
    velocities within 1e-9), and the cradles of 3 and 5 with their bodies reversed (the
    cradle law)."""
    import itertools
    r = 0.1
    th = math.radians(120)
    n = [np.array([1.0, 0.0, 0.0]), np.array([math.cos(th), math.sin(th), 0.0])]
    first = None
    for perm in itertools.permutations(range(3)):
        inv = np.argsort(perm)
        pos = [[0, 0, 0], 2 * r * n[0], 2 * r * n[1]]
        lin = [[0, 0, 0], -2 * n[0], -2 * n[1]]
        bodies = [sphere(f'b{i}', r, 1.0, e=1.0) for i in range(3)]
        before = states([pos[i] for i in perm], [lin[i] for i in perm])
        for flipped in (False, True):
            pick = slice(None, None, -1 if flipped else 1)
            contacts = contact_set([inv[0]] * 2, [inv[1], inv[2]][pick],
                                   [r * n[0], r * n[1]][pick], n[pick], 0.0,
                                   kind=ContactKind.IMPACT)
            world = World([bodies[i] for i in perm], SolverSettings(), FixedContacts(contacts))
            v = world.step(before, before.copy(), 0.01).states.linear[inv]
            first = v if first is None else first
            d = float(np.abs(v - first).max())
            row('order independence', f'three-ball hit, bodies {perm}, contacts '
                + ('reversed' if flipped else 'in order'), f'max |dv| {d:.1e} m/s', d < 1e-9)
    for touching in (3, 5):
        for rate in (30.0, 240.0):
            ratio, v, ok = cradle_answer(touching, rate, 0.05, 1.0, 0.004, reverse=True)
            row('order independence', f'cradle of {touching}, bodies reversed, {rate:g} Hz',
                f'E {ratio:.4f}, last {v[-1]:.3f} v0, others <= '
                f'{np.abs(v[:-1]).max():.3f} v0', ok)


def cradle_answer(touching: int, rate: float, r: float, mass: float, gap: float,
                  reverse: bool = False) -> tuple[float, np.ndarray, bool]:
    """A striker at v0 = 1 m/s, ``gap`` m from a row of ``touching`` balls (radius ``r``,
    ``mass``, e = 1, no gravity), its bodies listed in reverse if ``reverse``: the energy's
    ratio to its start, the balls' x-velocities in row order (in v0) and whether the cradle
    law holds (energy within 1 %, the last ball >= 0.95 v0, the others <= 0.05 v0)."""
    count = touching + 1
    x = [-2 * r - gap] + [2 * r * i for i in range(touching)]
    order = list(range(count))[::-1] if reverse else list(range(count))
    lin = np.zeros((count, 3))
    lin[0, 0] = 1.0
    sim = Simulation([sphere(f's{i}', r, mass, e=1.0) for i in order],
                     states([[x[i], 0.0, 0.0] for i in order], lin[order]), rate,
                     gravity=ZERO_G)
    e0 = sim.energy()
    for _ in range(max(8, int(0.3 * rate))):
        sim.step()
    v = sim.state.linear[np.argsort(order), 0]
    ratio = sim.energy() / e0
    ok = abs(ratio - 1) <= 0.01 and v[-1] >= 0.95 and bool(np.all(np.abs(v[:-1]) <= 0.05))
    return ratio, v, ok


@check('cradle_sizes')
def cradle_sizes() -> None:
    """The cradle law (energy within 1 %, the last ball >= 0.95 v0, the others <= 0.05 v0)
    with balls of 1 cm and 1 m, of 10 kg, and a striker touching the row at the start."""
    for touching in (3, 5):
        for rate in (30.0, 240.0):
            for r, mass, gap in ((0.01, 1.0, 0.001), (1.0, 1.0, 0.05), (0.05, 10.0, 0.004),
                                 (0.05, 1.0, 0.0)):
                ratio, v, ok = cradle_answer(touching, rate, r, mass, gap)
                row('cradle', f'{touching} touching, r {r}, m {mass}, gap {gap}, {rate:g} Hz',
                    f'E {ratio:.4f}, last {v[-1]:.3f} v0, others <= '
                    f'{np.abs(v[:-1]).max():.3f} v0', ok)


@check('stack_sizes')
def stack_sizes() -> None:
    """The 1000:1 and 100:1 stacks of cubes of 1 cm, 5 cm and 1 m move < 0.1 mm in 10 s
    (at 30 Hz a step's fall g dt^2, 11 mm, exceeds the 1 cm cubes' size)."""
    for size in (0.01, 0.05, 1.0):
        for ratio in (100.0, 1000.0):
            for rate in (30.0, 120.0, 240.0):
                bodies = [plane(), cube('light', size, 1.0), cube('heavy', size, ratio)]
                start = np.array([[0.0, 0.0, 0.0], [0.0, 0.0, size / 2],
                                  [0.0, 0.0, 1.5 * size]])
                moved, e0, highest = stand(bodies, start, rate=rate)
                row(f'{ratio:g}:1 stack', f'{size} m, {rate:g} Hz',
                    f'drift {moved * 1000:.4f} mm',
                    moved < 1e-4 and highest <= e0 + 1e-9 * abs(e0))


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--only', nargs='*', default=None, help=f'groups: {", ".join(CHECKS)}')
    parser.add_argument('--list', action='store_true')
    args = parser.parse_args(argv)
    if args.list:
        for name, fn in CHECKS.items():
            print(f'{name}: {fn.__doc__.split(chr(10))[0]}')
        return 0
    print('| law | case | figure | result |\n|---|---|---|---|', flush=True)
    for name in args.only or list(CHECKS):
        started = time.perf_counter()
        CHECKS[name]()
        print(f'<!-- {name}: {time.perf_counter() - started:.1f} s -->', flush=True)
    failed = [r for r in ROWS if not r[3]]
    print(f'\n{len(ROWS)} checks, {len(failed)} failed')
    return 1 if failed else 0


if __name__ == '__main__':
    sys.exit(main())
