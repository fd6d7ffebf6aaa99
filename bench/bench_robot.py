"""The robot scene in-process: the arm of config/scenes/arm.yaml (links kinematic, compounds
of their collision elements) sweeping through compound tables dropped on a floor, with
``--bin`` into the triangle-mesh bin test/data/meshes/bin.obj (40 one-sided triangles,
0.4 m square, 0.2 m tall) on that floor around the arm; core step time and contact rows
per step for several solver.max_contacts_per_pair.

The arm's shoulder and elbow follow q(t) = 0.9 sin(2 pi 0.5 t), -0.6 sin(2 pi 0.5 t) (link
poses by forward kinematics, their twists by finite differences); the tables (a top on two
legs, three boxes each) start in layers of four over the arm and fall, stack and get pushed
(``in_bin``: how many end inside the bin's walls; ``lowest_table_z``: none sank). Every
cap runs the same scene from the same start in its own child process.

Usage::

    .venv/bin/python bench/bench_robot.py [--tables 24] [--seconds 2] [--caps 4 8 1000] [--bin]
"""

from __future__ import annotations

import argparse
import subprocess
import sys

CHILD = r'''
import json, math, sys, time
from pathlib import Path
import numpy as np
root = Path(sys.argv[1])
tables, seconds, cap = int(sys.argv[2]), float(sys.argv[3]), int(sys.argv[4])
in_bin = sys.argv[5] == 'bin'
import yaml
from collres_ros.core.config import SolverSettings
from collres_ros.core.rotation import integrate, multiply
from collres_ros.core.types import BodyStates
from collres_ros.core.world import World
from collres_ros.ros import params, robot
scenes = root / 'config/scenes'
urdf = yaml.safe_load((scenes / 'arm.yaml').read_text())['/**']['ros__parameters'][
    'robot_description']
names = ['floor'] + ['bin'] * in_bin + [f't{k}' for k in range(tables)]
values = {'bodies': names, 'robot_description': urdf, 'body.floor.static': True,
          'body.floor.shape': 'box', 'body.floor.size': [3.0, 3.0, 0.2],
          'body.floor.position': [0.0, 0.0, -0.1], 'body.bin.static': True,
          'body.bin.shape': 'triangle_mesh',
          'body.bin.mesh': str(root / 'test/data/meshes/bin.obj'),
          'solver.max_contacts_per_pair': cap}
for k in range(tables):
    t = f'body.t{k}'
    values.update({f'{t}.shapes': ['top', 'left', 'right'], f'{t}.mass': 0.5,
                   f'{t}.position': [-0.1 + 0.2 * (k % 2), -0.06 + 0.12 * (k % 4 // 2),
                                     0.5 + 0.12 * (k // 4)]})
    for piece, size, pos in (('top', [0.16, 0.06, 0.02], [0, 0, 0.025]),
                             ('left', [0.02, 0.06, 0.08], [-0.07, 0, -0.025]),
                             ('right', [0.02, 0.06, 0.08], [0.07, 0, -0.025])):
        values.update({f'{t}.piece.{piece}.shape': 'box', f'{t}.piece.{piece}.size': size,
                       f'{t}.piece.{piece}.position': pos})
if not in_bin:
    values = {k: v for k, v in values.items() if not k.startswith('body.bin.')}
tables_ = [n for n in names if n.startswith('t')]
scene = params.scene_from_values(values, scenes)   # the finger mesh beside the scene
links = [n for n in scene.names if n not in names]
index = {n: scene.index(n) for n in scene.names}
world = World(scene.bodies, SolverSettings(max_contacts_per_pair=cap, sleeping=False),
              collision_filter=scene.collision_filter)
rate = 240.0; dt = 1.0 / rate; g = np.array([0, 0, -9.81])
def arm(t):
    s = math.sin(2 * math.pi * 0.5 * t)
    return robot.link_poses(urdf, {'shoulder': 0.9 * s, 'elbow': -0.6 * s})
state = scene.initial.copy()
for n, (p, q) in arm(0.0).items():
    if n in index: state.position[index[n]], state.orientation[index[n]] = p, q
dynamic = world.dynamic
times, rows = [], []
for step in range(int(seconds * rate)):
    t1 = (step + 1) * dt
    cur = state.copy()
    cur.linear[dynamic] += g * dt
    cur.position[dynamic] += cur.linear[dynamic] * dt
    cur.orientation[dynamic] = integrate(state.orientation[dynamic], state.angular[dynamic], dt)
    for n, (p, q) in arm(t1).items():
        if n not in index: continue
        i = index[n]
        cur.linear[i] = (p - state.position[i]) / dt
        dq = multiply(q, state.orientation[i] * [-1, -1, -1, 1])
        dq = dq if dq[3] >= 0 else -dq
        angle = 2 * math.atan2(np.linalg.norm(dq[:3]), dq[3])
        axis = dq[:3] / max(np.linalg.norm(dq[:3]), 1e-300)
        cur.angular[i] = axis * angle / dt
        cur.position[i], cur.orientation[i] = p, q
    start = time.perf_counter()
    result = world.step(state, cur, dt)
    times.append(time.perf_counter() - start)
    rows.append(result.report.contacts.count)
    state = result.states
times = np.array(times) * 1e3
print(json.dumps({'cap': cap, 'bin': in_bin, 'bodies': len(scene.names), 'links': len(links),
                  'step_ms_p50': float(np.median(times)),
                  'step_ms_p90': float(np.percentile(times, 90)),
                  'rows_mean': float(np.mean(rows)), 'rows_max': int(max(rows)),
                  'lowest_table_z': float(state.position[[index[n] for n in tables_], 2].min()),
                  'in_bin': int((np.abs(state.position[[index[n] for n in tables_], :2]) < 0.2)
                                .all(axis=1).sum()),
                  'finite': bool(np.isfinite(state.position).all())}))
'''


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--tables', type=int, default=24)
    parser.add_argument('--seconds', type=float, default=2.0)
    parser.add_argument('--caps', type=int, nargs='+', default=[4, 8, 1000])
    parser.add_argument('--bin', action='store_true',
                        help='the triangle-mesh bin around the arm instead of a box floor')
    args = parser.parse_args()
    from pathlib import Path
    root = Path(__file__).resolve().parents[1]
    with open('/proc/loadavg') as load:
        print(f'load: {load.read().strip()}')
    for cap in args.caps:
        out = subprocess.run([sys.executable, '-c', CHILD, str(root), str(args.tables),
                              str(args.seconds), str(cap), 'bin' if args.bin else 'floor'],
                             capture_output=True, text=True,
                             check=True)
        print(out.stdout.strip())
    with open('/proc/loadavg') as load:
        print(f'load: {load.read().strip()}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
