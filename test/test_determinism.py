"""Determinism: a fixed scene stepped N times gives a known hash of the states, bit for bit.

As Box2D's determinism sample: the billiard break (impacts, friction, many
simultaneous contacts) is integrated by the simulator's semi-implicit Euler and
resolved by the core for ``STEPS`` steps; the SHA-256 of every step's corrected
states and contact impulses must equal ``EXPECTED``. A change of the physics
(e.g. the compiled core) changes the hash on purpose: regenerate it with

    .venv/bin/python test/test_determinism.py

which prints the new value (paste it into ``EXPECTED`` and say why in the commit).
"""

from __future__ import annotations

import hashlib
import os
import subprocess
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
SCENE = ROOT / 'config' / 'scenes' / 'billiard_break.yaml'
STEPS = 240
# Regenerate: `.venv/bin/python test/test_determinism.py` (see the module docstring).
EXPECTED = '5148d4e52c222fd3956a098875028ef98376169523cf66f38e26c51c9d2f1bc3/1278'


def run_hash(steps: int = STEPS) -> str:
    """SHA-256 (hex) of the corrected states and impulses of ``steps`` steps of the scene,
    then ``/`` and the number of contacts solved (so that a run without contacts shows)."""
    from collres_ros.core.pipeline import Resolver
    from collres_ros.core.types import BodyInput
    from collres_ros.ros.integrator import euler_step
    from collres_ros.ros.params import load_scene
    scene = load_scene(SCENE)
    resolver = Resolver.for_scene(scene)
    states = scene.initial.copy()
    dynamic = np.array([not b.static for b in scene.bodies])
    gravity = np.array(scene.sim.gravity)
    dt_ns = int(round(1e9 / scene.sim.rate_hz))
    digest = hashlib.sha256()
    for k in range(steps):
        states = euler_step(states, dynamic, gravity, dt_ns * 1e-9)
        inputs = [BodyInput(b.name, tuple(states.position[i]), tuple(states.orientation[i]),
                            tuple(states.linear[i]), tuple(states.angular[i]), 'world', 'world')
                  for i, b in enumerate(scene.bodies)]
        out = resolver.resolve(10**9 + k * dt_ns, inputs)
        for name in ('position', 'orientation', 'linear', 'angular'):
            value = np.ascontiguousarray(getattr(out.states, name), dtype='<f8')
            getattr(states, name)[out.index] = value
            digest.update(value.tobytes())
        digest.update(np.ascontiguousarray(out.report.normal_impulse, '<f8').tobytes())
        digest.update(np.ascontiguousarray(out.report.friction_impulse, '<f8').tobytes())
    return f'{digest.hexdigest()}/{resolver.totals["contacts"]}'


def test_the_same_scene_gives_the_known_hash_bit_for_bit():
    first = run_hash()
    print('state hash', first, 'expected', EXPECTED)
    assert int(first.split('/')[1]) > 100, 'too few contacts: the solver was not exercised'
    assert run_hash() == first, 'two runs in one process differ'
    # another process with another hash seed (set and dict orders) gives the same bits
    code = f'import sys; sys.path.insert(0, {str(ROOT / "test")!r}); ' \
        'import test_determinism as t; print(t.run_hash())'
    other = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True,
                           env={**os.environ, 'PYTHONHASHSEED': '12345'}, timeout=600,
                           cwd=ROOT)
    assert other.stdout.strip() == first, other.stderr
    assert first == EXPECTED, (
        f'the state hash changed to {first}: if the physics changed on purpose, regenerate '
        'EXPECTED with `.venv/bin/python test/test_determinism.py`')


if __name__ == '__main__':
    print(run_hash())
