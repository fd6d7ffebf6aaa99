"""Step time of MuJoCo and PyBullet on a pile described by bench/pile.py (peer venv only).

Run with an interpreter that has ``mujoco`` and/or ``pybullet`` (never the
project's .venv): ``/tmp/peervenv/bin/python bench/peers.py SCENE.json``.
Prints one JSON line: {"mujoco": ms or null, "pybullet": ms or null}, the
median wall time of one full step (detection + solver + integration).
"""

from __future__ import annotations

import json
import statistics
import sys
import time


def _median_ms(step, warmup: int, steps: int) -> float:
    for _ in range(warmup):
        step()
    times = []
    for _ in range(steps):
        start = time.perf_counter()
        step()
        times.append(time.perf_counter() - start)
    return 1000.0 * statistics.median(times)


def _walls(scene: dict) -> list[tuple[list[float], list[float]]]:
    """(centre, half extents) of the floor slab and four wall slabs of the bin."""
    half = scene['half_width']
    thick, height = 0.05, 2.0
    return [([0.0, 0.0, -thick], [half + 1.0, half + 1.0, thick]),
            ([-half - thick, 0.0, height], [thick, half + 1.0, height]),
            ([half + thick, 0.0, height], [thick, half + 1.0, height]),
            ([0.0, -half - thick, height], [half + 1.0, thick, height]),
            ([0.0, half + thick, height], [half + 1.0, thick, height])]


def mujoco_ms(scene: dict, dt: float, warmup: int, steps: int) -> float | None:
    try:
        import mujoco
    except ImportError:
        return None
    parts = [f'<mujoco><option timestep="{dt}" gravity="0 0 -9.81" solver="CG"/><worldbody>']
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
    return _median_ms(lambda: mujoco.mj_step(model, data), warmup, steps)


def pybullet_ms(scene: dict, dt: float, warmup: int, steps: int) -> float | None:
    try:
        import pybullet as p
    except ImportError:
        return None
    client = p.connect(p.DIRECT)
    p.setGravity(0, 0, -9.81, physicsClientId=client)
    p.setTimeStep(dt, physicsClientId=client)
    for centre, half in _walls(scene):
        shape = p.createCollisionShape(p.GEOM_BOX, halfExtents=half, physicsClientId=client)
        p.createMultiBody(0.0, shape, basePosition=centre, physicsClientId=client)
    for i, body in enumerate(scene['bodies']):
        if body['static']:
            continue
        if body['shape'] == 'box':
            shape = p.createCollisionShape(p.GEOM_BOX, halfExtents=[s / 2 for s in body['size']],
                                           physicsClientId=client)
        else:
            shape = p.createCollisionShape(p.GEOM_SPHERE, radius=body['size'][0],
                                           physicsClientId=client)
        uid = p.createMultiBody(body['mass'], shape, basePosition=scene['position'][i],
                                baseOrientation=scene['orientation'][i], physicsClientId=client)
        p.changeDynamics(uid, -1, lateralFriction=body['mu'], restitution=body['e'],
                         physicsClientId=client)
    result = _median_ms(lambda: p.stepSimulation(physicsClientId=client), warmup, steps)
    p.disconnect(client)
    return result


def main() -> int:
    scene = json.load(open(sys.argv[1]))
    dt, warmup, steps = scene['dt'], scene['warmup'], scene['steps']
    print(json.dumps({'mujoco': mujoco_ms(scene, dt, warmup, steps),
                      'pybullet': pybullet_ms(scene, dt, warmup, steps)}))
    return 0


if __name__ == '__main__':
    sys.exit(main())
