"""Step time of MuJoCo (CG, Newton), PyBullet and Rapier on a pile described by bench/pile.py.

Run with the peers' throw-away interpreter (never the project's .venv; bench_step.py
creates it): ``PEER_PYTHON bench/peers.py SCENE.json``. Prints one JSON line, per
engine null when it is not installed, else {"ms": median wall time of one full step
(detection + solver + integration), "contacts": median contact points per step,
"steps": steps timed, ...}.

MuJoCo's step time depends on how many contacts it keeps and how many solver
iterations it needs (CG stops at 100), so both are reported with it, and the arena is
sized from the body count with its contact-full warnings counted (0: no contact was
dropped): an earlier figure of 4.66 ms at 1000 bodies could not be reproduced (about
100-180 ms with CG at its cap) and a time without these numbers cannot be checked.

Rapier (``rapier3d``, its official Python bindings: single precision, SIMD) runs with one
thread and sleeping off, as every other engine here, with its default solver settings
(reported as ``iterations``); its contact points are the active points of its manifolds.
"""

from __future__ import annotations

import json
import math
import statistics
import sys
import time

WARMUP_S = 10.0   # at most this long settling the pile in the peer before timing, s
TIMED_S = 20.0    # at most this long timing (at least 3 steps), s


def _timed(step, count, warmup: int, steps: int) -> dict:
    """Median ms per step and median contact points per step, within the time budgets."""
    start = time.perf_counter()
    for _ in range(warmup):
        step()
        if time.perf_counter() - start > WARMUP_S:
            break
    times, contacts = [], []
    start = time.perf_counter()
    while len(times) < steps and (len(times) < 3 or time.perf_counter() - start < TIMED_S):
        begin = time.perf_counter()
        step()
        times.append(time.perf_counter() - begin)
        contacts.append(count())
    return {'ms': 1000.0 * statistics.median(times), 'contacts': statistics.median(contacts),
            'steps': len(times)}


def _walls(scene: dict) -> list[tuple[list[float], list[float]]]:
    """(centre, half extents) of the floor slab and four wall slabs of the bin."""
    half = scene['half_width']
    thick, height = 0.05, 2.0
    return [([0.0, 0.0, -thick], [half + 1.0, half + 1.0, thick]),
            ([-half - thick, 0.0, height], [thick, half + 1.0, height]),
            ([half + thick, 0.0, height], [thick, half + 1.0, height]),
            ([0.0, -half - thick, height], [half + 1.0, thick, height]),
            ([0.0, half + thick, height], [half + 1.0, thick, height])]


def mujoco_run(scene: dict, solver: str, warmup: int, steps: int) -> dict | None:
    try:
        import mujoco
    except ImportError:
        return None
    dynamic = sum(1 for b in scene['bodies'] if not b['static'])
    memory = max(64, dynamic // 4)      # MB: ~40 contacts of a few KB each per body, roomy
    parts = [f'<mujoco><option timestep="{scene["dt"]}" gravity="0 0 -9.81" '
             f'solver="{solver}"/><size memory="{memory}M"/><worldbody>']
    for centre, half in _walls(scene):
        parts.append('<geom type="box" pos="{} {} {}" size="{} {} {}"/>'.format(*centre, *half))
    for i, body in enumerate(scene['bodies']):
        if body['static']:
            continue
        x, y, z = scene['position'][i]
        qx, qy, qz, qw = scene['orientation'][i]
        if body['shape'] == 'box':
            geom = 'type="box" size="{} {} {}"'.format(*[s / 2 for s in body['size']])
        else:
            geom = f'type="sphere" size="{body["size"][0]}"'
        parts.append(f'<body pos="{x} {y} {z}" quat="{qw} {qx} {qy} {qz}"><freejoint/>'
                     f'<geom {geom} mass="{body["mass"]}" friction="{body["mu"]}"/></body>')
    parts.append('</worldbody></mujoco>')
    model = mujoco.MjModel.from_xml_string(''.join(parts))
    data = mujoco.MjData(model)
    iterations = []

    def step() -> None:
        mujoco.mj_step(model, data)
        iterations.append(int(data.solver_niter[0]))

    result = _timed(step, lambda: int(data.ncon), warmup, steps)
    result['iterations'] = statistics.median(iterations[-result['steps']:])
    result['contact_full'] = int(data.warning[mujoco.mjtWarning.mjWARN_CONTACTFULL].number)
    return result


def pybullet_shape(p, body: dict, client: int) -> int:
    """PyBullet's collision shape of a box (``size``: full extents, m) or a sphere (``size``:
    its radius first) in the connection ``client`` of the ``pybullet`` module ``p``."""
    if body['shape'] == 'box':
        return p.createCollisionShape(p.GEOM_BOX, halfExtents=[s / 2 for s in body['size']],
                                      physicsClientId=client)
    return p.createCollisionShape(p.GEOM_SPHERE, radius=body['size'][0], physicsClientId=client)


def pybullet_run(scene: dict, warmup: int, steps: int) -> dict | None:
    try:
        import pybullet as p
    except ImportError:
        return None
    client = p.connect(p.DIRECT)
    p.setGravity(0, 0, -9.81, physicsClientId=client)
    p.setTimeStep(scene['dt'], physicsClientId=client)
    for centre, half in _walls(scene):
        shape = p.createCollisionShape(p.GEOM_BOX, halfExtents=half, physicsClientId=client)
        p.createMultiBody(0.0, shape, basePosition=centre, physicsClientId=client)
    for i, body in enumerate(scene['bodies']):
        if body['static']:
            continue
        shape = pybullet_shape(p, body, client)
        uid = p.createMultiBody(body['mass'], shape, basePosition=scene['position'][i],
                                baseOrientation=scene['orientation'][i], physicsClientId=client)
        p.changeDynamics(uid, -1, lateralFriction=body['mu'], restitution=body['e'],
                         physicsClientId=client)
    result = _timed(lambda: p.stepSimulation(physicsClientId=client),
                    lambda: len(p.getContactPoints(physicsClientId=client)), warmup, steps)
    p.disconnect(client)
    return result


def scaled_axis(q: list[float]) -> tuple[float, float, float]:
    """Rotation vector (axis times angle, rad) of a unit quaternion x, y, z, w."""
    x, y, z, w = q
    s = math.sqrt(x * x + y * y + z * z)
    if s < 1e-12:
        return (0.0, 0.0, 0.0)
    angle = 2.0 * math.atan2(s, w)
    return (x / s * angle, y / s * angle, z / s * angle)


def rapier_run(scene: dict, warmup: int, steps: int) -> dict | None:
    try:
        import rapier3d as r
    except ImportError:
        return None
    world = r.PhysicsWorld(gravity=(0.0, 0.0, -9.81))
    world.set_num_threads(1)
    world.integration_parameters.dt = scene['dt']
    for centre, half in _walls(scene):
        world.add_body(r.RigidBody.fixed().translation(tuple(centre)),
                       [r.Collider.cuboid(*half)])
    for i, body in enumerate(scene['bodies']):
        if body['static']:
            continue
        rigid = r.RigidBody.dynamic().translation(tuple(scene['position'][i])) \
            .rotation(scaled_axis(scene['orientation'][i])).can_sleep(False)
        if body['shape'] == 'box':
            collider = r.Collider.cuboid(*[s / 2 for s in body['size']])
        else:
            collider = r.Collider.ball(body['size'][0])
        world.add_body(rigid, [collider.mass(body['mass']).friction(body['mu'])
                               .restitution(body['e'])])

    def count() -> int:
        return sum(m.data.num_active_contacts for pair in world.narrow_phase.contact_pairs()
                   for m in pair.manifolds)

    result = _timed(world.step, count, warmup, steps)
    result['iterations'] = int(world.integration_parameters.num_solver_iterations)
    return result


def main() -> int:
    scene = json.load(open(sys.argv[1]))
    warmup, steps = scene['warmup'], scene['steps']
    print(json.dumps({'mujoco_cg': mujoco_run(scene, 'CG', warmup, steps),
                      'mujoco_newton': mujoco_run(scene, 'Newton', warmup, steps),
                      'pybullet': pybullet_run(scene, warmup, steps),
                      'rapier': rapier_run(scene, warmup, steps)}))
    return 0


if __name__ == '__main__':
    sys.exit(main())
