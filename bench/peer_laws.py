"""The issue's contact laws on our core and on Rapier, MuJoCo and PyBullet, side by side.

    .venv/bin/python bench/peer_laws.py [--quick] [--peer-venv DIR] [--sweeps 4 6]

Each scene is built once as plain data (bodies, sizes, masses, friction, restitution, initial
poses and twists, gravity, rate) and stepped by every engine for the same time at the same
dt; every engine's trajectory (poses and twists of the movable bodies after each step) is
judged by the same code against the law. Ours is collres_ros.core's World closed by the
tests' semi-implicit Euler integrator (test/core/integrator.py), the scenes as
bench/bench_laws.py builds them (its helpers and those of test/core); the peers run in their
throw-away interpreter (``--peer-venv``, the one bench/bench_step.py sets up), which runs this
file with ``--peer`` and imports nothing of collres_ros.

Peers' settings: their defaults (Rapier ``rapier3d``: 4 solver iterations, one thread; MuJoCo:
each of its solvers, Newton (its default), PGS and CG, the table shows the one that passes the
most laws; PyBullet: 50 iterations) except:

* sleeping off for every engine (ours too): the solver's answer is judged, not the sleepers';
* every pair of bodies of a scene gets the scene's friction and restitution whatever the
  engine's combine rule (PyBullet multiplies the two bodies' coefficients: each body gets
  the square root; Rapier averages and MuJoCo takes the larger: each body gets the value);
  the peers' one friction coefficient is our static one (what holds a body at rest);
* PyBullet's default linear and angular damping (0.04 each) set to 0: no other engine
  damps a free body;
* MuJoCo has no restitution coefficient: a scene with e > 0 gets contacts of solref
  (-k, -b), a spring of natural frequency pi / (4 dt) (an impact lasts about four steps, its
  time constant twice the step, the least MuJoCo advises) with the damping ratio of a
  spring that returns e of the approach speed, -ln e / sqrt(pi^2 + ln^2 e); e = 0 keeps its
  default solref;
* floors and walls: planes where the engine has them (MuJoCo's and PyBullet's, Rapier's
  half-space), the gas's walls boxes as ours.

Prints one markdown table: law | bound | ours | Rapier | MuJoCo | PyBullet, each cell the
measured figure and pass / FAIL. ``--sweeps N ...`` adds a column of ours at a budget of
Rapier's kind: ``velocity_iterations`` N and no floor of sweeps per level of the deepest stack
(SOLVER_TUNING ``depth_sweeps`` 0; the defaults stay 10 and 1.5). ``--quick`` runs one rate
per scene.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
G = 9.81
ENGINES = ('rapier', 'mujoco', 'pybullet')
MUJOCO_SOLVERS = ('Newton', 'PGS', 'CG')


# ---------------------------------------------------------------- scenes (plain data)

def _body(shape: str, size, mass: float, position, linear=(0.0, 0.0, 0.0),
          orientation=(0.0, 0.0, 0.0, 1.0), static: bool = False) -> dict:
    return {'shape': shape, 'size': [float(s) for s in size], 'mass': float(mass),
            'static': static, 'position': [float(x) for x in position],
            'linear': [float(x) for x in linear],
            'orientation': [float(x) for x in orientation]}


def scene_from(specs, state, rate: float, duration: float, gravity) -> dict:
    """The plain description of bodies ``specs`` (BodySpec) at ``state`` (BodyStates): the
    scene's friction and restitution are its movable bodies' (all alike)."""
    movable = [s for s in specs if not s.static]
    mu = {s.static_friction for s in movable}
    e = {s.restitution for s in movable}
    assert len(mu) == 1 and len(e) == 1, 'one material per scene'
    assert not np.any(state.angular), 'the peers start without spin'
    bodies = [_body(s.shape, s.size, s.mass if not s.static else 0.0, state.position[i],
                    state.linear[i], state.orientation[i], s.static)
              for i, s in enumerate(specs)]
    return {'rate': rate, 'steps': int(round(duration * rate)), 'gravity': list(gravity),
            'mu': mu.pop(), 'e': e.pop(), 'bodies': bodies}


# ---------------------------------------------------------------- the peers (their venv)

def _plane_pose(size) -> tuple[list[float], list[float]]:
    """(normal, a point) of a plane n . x = d."""
    n = np.asarray(size[:3], float)
    return n.tolist(), (n * size[3]).tolist()


def _quat_rotate(q, v) -> np.ndarray:
    """v rotated by the unit quaternion q (x, y, z, w)."""
    u, w = np.asarray(q[:3]), q[3]
    return v + 2.0 * np.cross(u, np.cross(u, v) + w * v)


def run_rapier(scene: dict):
    import rapier3d as r
    from peers import scaled_axis   # (this file's directory: its peer mode too)
    world = r.PhysicsWorld(gravity=tuple(scene['gravity']))
    world.set_num_threads(1)
    world.integration_parameters.dt = 1.0 / scene['rate']
    handles = []
    for b in scene['bodies']:
        if b['shape'] == 'plane':
            normal, point = _plane_pose(b['size'])
            world.add_body(r.RigidBody.fixed().translation(tuple(point)),
                           [r.Collider.halfspace(tuple(normal)).friction(scene['mu'])
                            .restitution(scene['e'])])
            continue
        builder = r.RigidBody.fixed() if b['static'] else \
            r.RigidBody.dynamic().linvel(tuple(b['linear'])).can_sleep(False)
        builder = builder.translation(tuple(b['position'])) \
            .rotation(scaled_axis(b['orientation']))
        collider = r.Collider.cuboid(*[s / 2 for s in b['size']]) if b['shape'] == 'box' \
            else r.Collider.ball(b['size'][0])
        if not b['static']:
            collider = collider.mass(b['mass'])
        handle = world.add_body(builder, [collider.friction(scene['mu'])
                                          .restitution(scene['e'])])
        if not b['static']:
            handles.append(handle)

    def read():
        out = []
        for h in handles:
            body = world.rigid_bodies[h]
            t, q, v, w = body.translation, body.rotation, body.linvel, body.angvel
            out.append([t.x, t.y, t.z, q.i, q.j, q.k, q.w, v.x, v.y, v.z, w.x, w.y, w.z])
        return out
    return _record(world.step, read, scene['steps'])


def _mujoco_solref(scene: dict) -> str:
    if scene['e'] <= 0.0:
        return ''
    dt = 1.0 / scene['rate']
    log = math.log(scene['e'])
    ratio = -log / math.sqrt(math.pi ** 2 + log * log)
    omega = math.pi / (4.0 * dt)
    # both negative (the direct form); a damping of exactly 0 reads as the other form
    return f' solref="{-omega * omega} {-max(2.0 * ratio * omega, 1e-9)}"'


def run_mujoco(scene: dict, solver: str):
    import mujoco
    material = f'friction="{scene["mu"]} 0.005 0.0001"{_mujoco_solref(scene)}'
    movable = sum(1 for b in scene['bodies'] if not b['static'])
    head = '<mujoco><option timestep="{}" gravity="{} {} {}" solver="{}"/><size memory="{}M"/>'
    parts = [head.format(1.0 / scene['rate'], *scene['gravity'], solver, max(64, movable // 4)),
             '<worldbody>']
    for b in scene['bodies']:
        x, y, z, w = b['orientation']
        pose = 'pos="{} {} {}" quat="{} {} {} {}"'.format(*b['position'], w, x, y, z)
        if b['shape'] == 'plane':
            normal, point = _plane_pose(b['size'])
            geom = 'type="plane" size="0 0 1" pos="{} {} {}" zaxis="{} {} {}"'.format(
                *point, *normal)
        elif b['shape'] == 'box':
            geom = 'type="box" size="{} {} {}"'.format(*[s / 2 for s in b['size']])
        else:
            geom = f'type="sphere" size="{b["size"][0]}"'
        if b['shape'] == 'plane':
            parts.append(f'<geom {geom} {material}/>')
        elif b['static']:
            parts.append(f'<geom {geom} {pose} {material}/>')
        else:
            parts.append(f'<body {pose}><freejoint/><geom {geom} mass="{b["mass"]}" '
                         f'{material}/></body>')
    parts.append('</worldbody></mujoco>')
    model = mujoco.MjModel.from_xml_string(''.join(parts))
    data = mujoco.MjData(model)
    movable = [b for b in scene['bodies'] if not b['static']]
    for k, b in enumerate(movable):
        data.qvel[6 * k:6 * k + 3] = b['linear']

    def read():
        out = []
        for k in range(len(movable)):
            p = data.qpos[7 * k:7 * k + 7]
            q = [p[4], p[5], p[6], p[3]]
            # a free joint's angular velocity is in the body's frame
            w = _quat_rotate(q, np.asarray(data.qvel[6 * k + 3:6 * k + 6]))
            out.append([*p[:3], *q, *data.qvel[6 * k:6 * k + 3], *w])
        return out
    return _record(lambda: mujoco.mj_step(model, data), read, scene['steps'])


def run_pybullet(scene: dict):
    import pybullet as p
    from peers import pybullet_shape   # (this file's directory: its peer mode too)
    client = p.connect(p.DIRECT)
    p.setGravity(*scene['gravity'], physicsClientId=client)
    p.setTimeStep(1.0 / scene['rate'], physicsClientId=client)
    # PyBullet multiplies the two bodies' coefficients: each gets the square root
    mu, e = math.sqrt(scene['mu']), math.sqrt(scene['e'])
    ids = []
    for b in scene['bodies']:
        if b['shape'] == 'plane':
            normal, point = _plane_pose(b['size'])
            shape = p.createCollisionShape(p.GEOM_PLANE, planeNormal=normal,
                                           physicsClientId=client)
            uid = p.createMultiBody(0.0, shape, basePosition=point, physicsClientId=client)
        else:
            shape = pybullet_shape(p, b, client)
            uid = p.createMultiBody(b['mass'], shape, basePosition=b['position'],
                                    baseOrientation=b['orientation'], physicsClientId=client)
        p.changeDynamics(uid, -1, lateralFriction=mu, restitution=e, linearDamping=0.0,
                         angularDamping=0.0, physicsClientId=client)
        if not b['static']:
            p.changeDynamics(uid, -1, activationState=p.ACTIVATION_STATE_DISABLE_SLEEPING,
                             physicsClientId=client)
            p.resetBaseVelocity(uid, b['linear'], [0.0, 0.0, 0.0], physicsClientId=client)
            ids.append(uid)

    def read():
        out = []
        for uid in ids:
            pos, q = p.getBasePositionAndOrientation(uid, physicsClientId=client)
            v, w = p.getBaseVelocity(uid, physicsClientId=client)
            out.append([*pos, *q, *v, *w])
        return out
    try:
        return _record(lambda: p.stepSimulation(physicsClientId=client), read, scene['steps'])
    finally:
        p.disconnect(client)


def _record(step, read, steps: int) -> np.ndarray:
    """(steps + 1, bodies, 13): position, orientation x y z w, linear, angular velocity (world
    frame) of the movable bodies at the start and after each step."""
    out = [read()]
    for _ in range(steps):
        step()
        out.append(read())
    return np.asarray(out, float)


def peer_main(scenes_file: str, out_dir: str) -> int:
    """Every scene of ``scenes_file`` on every peer: ``out_dir``/<scene>.<engine>.npy, or a
    <scene>.<engine>.err with the reason."""
    scenes = json.load(open(scenes_file))
    runs = [('rapier', run_rapier)] + \
        [(f'mujoco_{s}', lambda scene, s=s: run_mujoco(scene, s)) for s in MUJOCO_SOLVERS] + \
        [('pybullet', run_pybullet)]
    for name, scene in scenes.items():
        for engine, run in runs:
            base = os.path.join(out_dir, f'{name}.{engine}')
            try:
                np.save(base + '.npy', run(scene))
            except Exception as error:     # an engine that cannot: said in the table
                open(base + '.err', 'w').write(f'{type(error).__name__}: {error}')
    return 0


# ---------------------------------------------------------------- ours and the scenes

def _ours_imports():
    sys.path.insert(0, str(HERE.parent))
    sys.path.insert(0, str(HERE.parent / 'test' / 'core'))
    sys.path.insert(0, str(HERE))


def ours(sim, steps: int) -> np.ndarray:
    """The same record as the peers' of a test/core Simulation, ``steps`` steps."""
    movable = np.flatnonzero(sim.dynamic)

    def read():
        s = sim.state
        return np.concatenate([s.position, s.orientation, s.linear, s.angular], 1)[movable]
    return _record(sim.step, read, steps)


class Scene:
    """A scene: its plain description for the peers, our Simulation, its law and bound."""

    def __init__(self, name, law, bound, sim, duration, judge, rate):
        from collres_ros.core.shapes import mass_properties
        self.name, self.law, self.bound, self.sim, self.judge = name, law, bound, sim, judge
        specs = sim.world.specs
        self.plain = scene_from(specs, sim.state, rate, duration,
                                sim.gravity.tolist())
        self.steps = self.plain['steps']
        movable = [s for s in specs if not s.static]
        self.mass = np.array([s.mass for s in movable])
        self.inertia = np.array([1.0 / np.diag(mass_properties(s)[1]) for s in movable])
        self.reach = np.array([s.size[0] if s.shape == 'sphere'
                               else 0.5 * float(np.linalg.norm(s.size)) for s in movable])

    def kinetic(self, rec: np.ndarray) -> np.ndarray:
        """Kinetic energy (J) at each record."""
        q, v, w = rec[..., 3:7], rec[..., 7:10], rec[..., 10:13]
        u, s = q[..., :3], q[..., 3:4]
        # the angular velocity in the body's frame: rotated by the conjugate
        wb = w + 2.0 * np.cross(-u, np.cross(-u, w) + s * w)
        return 0.5 * (self.mass * (v * v).sum(-1)).sum(-1) + \
            0.5 * (self.inertia * wb * wb).sum(-1).sum(-1)


def build_scenes(quick: bool, iterations: int | None = None) -> list[Scene]:
    """The scenes; ours at ``iterations`` velocity sweeps a substep (no depth floor) if given."""
    _ours_imports()
    from collres_ros.core.config import SolverSettings
    from collres_ros.core.rotation import to_matrix
    from bench_laws import cube, newton, plane
    from contacts import box, sphere, states
    from integrator import Simulation
    from pile import make_pile
    from test_hovering import corners
    from test_impact_laws import elastic_gas, GAS_SIDE

    def settings(**kw):
        kw.setdefault('sleeping', False)
        if iterations is not None:
            kw['velocity_iterations'] = iterations
        return SolverSettings(**kw)

    zero_g = np.zeros(3)
    scenes = []

    # 1. cradles
    def cradle_judge(rec, sc):
        e0, e1 = sc.kinetic(rec[0]), sc.kinetic(rec[-1])
        v = rec[-1, :, 7]
        ok = abs(e1 / e0 - 1) <= 0.01 and v[-1] >= 0.95 and np.all(np.abs(v[:-1]) <= 0.05)
        return f'E {e1 / e0:.3f}, last {v[-1]:.3f}, others <= {np.abs(v[:-1]).max():.3f}', ok
    for touching, rate in ((3, 240.0), (5, 240.0), (5, 60.0)):
        if quick and rate != 240.0:
            continue
        r = 0.05
        x = [-2 * r - 0.004] + [2 * r * i for i in range(touching)]
        lin = [[1.0, 0, 0]] + [[0.0] * 3] * touching
        sim = Simulation([sphere(f's{i}', r, 1.0, e=1.0) for i in range(touching + 1)],
                         states([[xi, 0, 0] for xi in x], lin), rate, settings(),
                         gravity=zero_g)
        scenes.append(Scene(f'cradle{touching}@{rate:g}', f'cradle of {touching}, '
                            f'{rate:g} Hz', 'E +-1 %, last >= 0.95 v0, others <= 0.05 v0',
                            sim, 0.3, cradle_judge, rate))

    # 2. the symmetric three-ball hit (120 deg, 2 m/s each, e = 1)
    r, v0 = 0.1, 2.0
    th = math.radians(120)
    n = [np.array([1.0, 0, 0]), np.array([math.cos(th), math.sin(th), 0])]
    impulse = newton(n, [1.0, 1.0], 1.0, [-v0, -v0])
    law_v = np.array([-(impulse[0] * n[0] + impulse[1] * n[1]),
                      -v0 * n[0] + impulse[0] * n[0], -v0 * n[1] + impulse[1] * n[1]])
    mirror = np.array([[math.cos(th), math.sin(th), 0], [math.sin(th), -math.cos(th), 0],
                       [0, 0, 1]])

    def three_judge(rec, sc):
        e0, e1 = sc.kinetic(rec[0]), sc.kinetic(rec[-1])
        v = rec[-1, :, 7:10]
        dev = np.abs(v - law_v).max() / v0
        asym = np.abs(mirror @ v[1] - v[2]).max() / v0
        ok = abs(e1 / e0 - 1) <= 0.01 and dev <= 0.01 and asym <= 1e-4
        return f'E {e1 / e0:.4f}, Newton {dev:.1e} v0, mirror {asym:.1e} v0', ok
    for rate in (240.0, 60.0):
        if quick and rate != 240.0:
            continue
        gap = 0.004
        pos = [[0, 0, 0], (2 * r + gap) * n[0], (2 * r + gap) * n[1]]
        sim = Simulation([sphere(f'b{i}', r, 1.0, e=1.0) for i in range(3)],
                         states(pos, [[0, 0, 0], -v0 * n[0], -v0 * n[1]]), rate, settings(),
                         gravity=zero_g)
        scenes.append(Scene(f'three@{rate:g}', f'three-ball hit 120 deg, {rate:g} Hz',
                            'E +-1 %, Newton +-0.01 v0, mirror 1e-4 v0', sim, 0.3,
                            three_judge, rate))

    # 3. the elastic gas
    def gas_judge(rec, sc):
        ratio = sc.kinetic(rec) / sc.kinetic(rec[0])
        inside = np.abs(rec[:, :, :3]).max() < GAS_SIDE / 2
        ok = ratio.min() >= 0.99 and ratio.max() <= 1.005 and inside
        return f'E {ratio.min():.3f}..{ratio.max():.3f}' + ('' if inside else ', escaped'), ok
    for rate in (60.0, 240.0):
        if quick and rate != 60.0:
            continue
        gas = elastic_gas(rate, SolverSettings().restitution_threshold)
        sim = Simulation(gas.world.specs, gas.state, rate, settings(), gravity=zero_g)
        scenes.append(Scene(f'gas@{rate:g}', f'elastic gas of 40, 5 s, {rate:g} Hz',
                            'E 0.99..1.005', sim, 5.0, gas_judge, rate))

    # 4. towers of 20 cubes of 0.2 m, 5. the 1000:1 stack
    size = 0.2

    def tower_judge(rec, sc):
        top = np.linalg.norm(rec[:, -1, :2] - rec[0, -1, :2], axis=1).max()
        moved = np.linalg.norm(rec[:, :, :3] - rec[0, :, :3], axis=2).max()
        return f'top {top * 1000:.3f} mm (any 3D {moved * 1000:.2f} mm)', top < 0.005

    def stack_judge(rec, sc):
        moved = np.linalg.norm(rec[:, :, :3] - rec[0, :, :3], axis=2).max()
        side = np.linalg.norm(rec[:, :, :2] - rec[0, :, :2], axis=2).max()
        return f'{moved * 1000:.3f} mm (sideways {side * 1000:.3f})', moved < 1e-4
    for rate in (60.0, 240.0):
        if quick and rate != 60.0:
            continue
        start = np.array([[0.0, 0, 0]] + [[0, 0, size * (i + 0.5)] for i in range(20)])
        sim = Simulation([plane()] + [cube(f'c{i}', size) for i in range(20)],
                         states(start, np.zeros_like(start)), rate, settings())
        scenes.append(Scene(f'tower@{rate:g}', f'tower of 20 cubes 0.2 m, 10 s, {rate:g} Hz',
                            "top's sideways drift < 5 mm", sim, 10.0, tower_judge, rate))
        start = np.array([[0.0, 0, 0], [0, 0, size / 2], [0, 0, 1.5 * size]])
        sim = Simulation([plane(), cube('light', size, 1.0), cube('heavy', size, 1000.0)],
                         states(start, np.zeros_like(start)), rate, settings())
        scenes.append(Scene(f'stack@{rate:g}', f'1000:1 stack, 10 s, {rate:g} Hz',
                            'moves < 0.1 mm', sim, 10.0, stack_judge, rate))

    # 6. a ball of 0.1 m dropped from 0.3 m, e 0.8, 240 Hz
    r, h, e, rate = 0.1, 0.3, 0.8, 240.0
    t0 = math.sqrt(2 * h / G)
    limit = t0 * (1 + e) / (1 - e)

    def rest_judge(rec, sc, r=r, h=h, e=e, rate=rate):
        height = rec[:, 0, 2] - r
        vz = rec[:, 0, 9]
        still = (np.abs(height - height[-1]) < 1e-4) & (np.abs(vz) < 0.01)
        moving = np.flatnonzero(~still)
        t = (moving[-1] + 1) / rate if len(moving) else 0.0
        first = height[int(1.2 * t0 * rate):int(2.4 * t0 * rate) + 1].max() \
            if len(height) > 2.4 * t0 * rate else 0.0
        ok = moving[-1] + 1 < len(height) - 1 and t <= limit + 8 / rate and \
            abs(first / (e * e * h) - 1) <= 0.02 + G / (8 * rate * rate) / (e * e * h)
        return f'rests {t:.2f} s, 1st apex {first / h:.3f} h', bool(ok)
    sim = Simulation([plane(e=0.0), sphere('ball', r, 1.0, e=e)],
                     states([[0, 0, 0], [0, 0, h + r]], np.zeros((2, 3))), rate, settings())
    scenes.append(Scene('rest@240', 'ball from 0.3 m, e 0.8, 240 Hz',
                        f'rests <= t0(1+e)/(1-e) = {limit:.2f} s, apex e^2 h +-2 %', sim,
                        4.0, rest_judge, rate))

    # 7. a cube of 0.2 m dropped on an edge (40 deg about x) from 5 cm
    cube_size = (0.2, 0.2, 0.2)
    local = corners(cube_size)

    def hover_judge(rec, sc):
        last = rec[-1, 0]
        rot = to_matrix(last[3:7])
        points = local @ rot.T
        heights = np.sort(points[:, 2] + last[2])[:4]
        speed = np.linalg.norm(last[7:10] + np.cross(last[10:13], points), axis=1).max()
        ok = heights.max() <= 1e-4 and speed < 1e-3
        return (f'corners {heights.min() * 1000:+.2f}..{heights.max() * 1000:+.2f} mm, '
                f'{speed:.0e} m/s'), ok
    for rate in (60.0, 240.0):
        if quick and rate != 60.0:
            continue
        half = math.radians(40) / 2
        q = np.array([math.sin(half), 0, 0, math.cos(half)])
        lowest = (local @ to_matrix(q).T)[:, 2].min()
        sim = Simulation([plane(0.5, 0.3), box('box', cube_size, 1.0, e=0.0, mu_s=0.5,
                                               mu_k=0.3)],
                         states([[0, 0, 0], [0, 0, 0.05 - lowest]], np.zeros((2, 3)),
                                orientation=[[0, 0, 0, 1], q]), rate, settings())
        scenes.append(Scene(f'hover@{rate:g}', f'cube dropped on an edge, 3 s, {rate:g} Hz',
                            'lowest 4 corners <= +0.1 mm, at rest', sim, 3.0, hover_judge,
                            rate))

    # 8. the mixed pile of 100, 2 s after the drop
    def pile_judge(rec, sc):
        last = rec[-1]
        speed = np.linalg.norm(last[:, 7:10], axis=1) + \
            np.linalg.norm(last[:, 10:13], axis=1) * sc.reach
        return f'{speed.max():.3f} m/s', speed.max() < 0.05
    for rate in (120.0, 60.0):
        if quick and rate != 120.0:
            continue
        bodies, initial = make_pile(100, seed=1, kind='mixed')
        sim = Simulation(bodies, initial, rate, settings())
        scenes.append(Scene(f'pile@{rate:g}', f'mixed pile of 100 at 2 s, {rate:g} Hz',
                            "fastest point < 0.05 m/s", sim, 2.0, pile_judge, rate))
    if iterations is not None:
        # velocity_iterations alone leaves the floor of depth_sweeps sweeps per level of the
        # deepest stack (a settled pile of 100 keeps its 22 sweeps a step at 4): none
        for sc in scenes:
            sc.sim.world._params.depth_sweeps = 0.0
    return scenes


def peer_python(venv: Path) -> Path | None:
    from bench_step import peer_python as setup
    return setup(venv)


def main(argv=None) -> int:
    if argv is None and len(sys.argv) > 1 and sys.argv[1] == '--peer':
        return peer_main(sys.argv[2], sys.argv[3])
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--quick', action='store_true', help='one rate per scene')
    cache = Path(os.environ.get('XDG_CACHE_HOME', Path.home() / '.cache'))
    parser.add_argument('--peer-venv', type=Path, default=Path(os.environ.get(
        'COLLRES_PEER_VENV', cache / 'collres_ros' / 'peer-venv')))
    parser.add_argument('--sweeps', type=int, nargs='*', default=[],
                        help='also ours at these velocity_iterations, depth_sweeps 0')
    args = parser.parse_args(argv)
    _ours_imports()
    scenes = build_scenes(args.quick)
    python = peer_python(args.peer_venv)
    records = {}
    with tempfile.TemporaryDirectory() as tmp:
        started = time.perf_counter()
        peers = None
        if python is not None:
            with open(os.path.join(tmp, 'scenes.json'), 'w') as handle:
                json.dump({s.name: s.plain for s in scenes}, handle)
            peers = subprocess.Popen([str(python), __file__, '--peer', handle.name, tmp])
        for sc in scenes:
            records[sc.name, 'ours'] = ours(sc.sim, sc.steps)
        for n in args.sweeps:
            for sc in build_scenes(args.quick, n):
                records[sc.name, f'ours{n}'] = ours(sc.sim, sc.steps)
        if peers is not None:
            peers.wait()
        for sc in scenes:
            for engine in ['rapier', 'pybullet'] + [f'mujoco_{s}' for s in MUJOCO_SOLVERS]:
                base = os.path.join(tmp, f'{sc.name}.{engine}')
                if os.path.exists(base + '.npy'):
                    records[sc.name, engine] = np.load(base + '.npy')
                elif os.path.exists(base + '.err'):
                    records[sc.name, engine] = open(base + '.err').read()
        elapsed = time.perf_counter() - started

    def cell(sc, engine):
        rec = records.get((sc.name, engine))
        if rec is None:
            return 'not run', False
        if isinstance(rec, str):
            return f'cannot: {rec}', False
        if not np.all(np.isfinite(rec)):
            return 'blew up (not finite)', False
        figure, ok = sc.judge(rec, sc)
        return f'{figure} {"pass" if ok else "FAIL"}', bool(ok)

    passes = {s: sum(cell(sc, f'mujoco_{s}')[1] for sc in scenes) for s in MUJOCO_SOLVERS}
    best = max(MUJOCO_SOLVERS, key=lambda s: (passes[s], -MUJOCO_SOLVERS.index(s)))
    columns = ['ours'] + [f'ours{n}' for n in args.sweeps] + \
        ['rapier', f'mujoco_{best}', 'pybullet']
    titles = ['ours'] + [f'ours, {n} sweeps' for n in args.sweeps] + \
        ['Rapier', f'MuJoCo ({best})', 'PyBullet']
    print('| law | bound | ' + ' | '.join(titles) + ' |')
    print('|---|---|' + '---|' * len(titles))
    totals = dict.fromkeys(columns, 0)
    for sc in scenes:
        cells = []
        for column in columns:
            text, ok = cell(sc, column)
            totals[column] += ok
            cells.append(text)
        print(f'| {sc.law} | {sc.bound} | ' + ' | '.join(cells) + ' |')
    print('| passed | | ' + ' | '.join(f'{totals[c]} of {len(scenes)}' for c in columns)
          + ' |')
    print('MuJoCo solvers, laws passed: '
          + ', '.join(f'{s} {passes[s]}' for s in MUJOCO_SOLVERS)
          + f'; {elapsed:.0f} s')
    return 0


if __name__ == '__main__':
    sys.exit(main())
