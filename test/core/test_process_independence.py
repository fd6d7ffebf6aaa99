"""A World's contacts do not depend on what its process ran before.

coal's box support function fixes an inflate factor on its first call in a process
(1 + 1e-10 when that call's direction has a zero component, as a box resting on a plane
asks, else 1) and grows every later box by it; the compiled core pins it to 1 at import
(src/shapes.h, pin_box_support). The laws, each in fresh processes:

* a pile of 100 cubes (``bench/pile.py``) gives the same contacts, byte for byte, on its
  first detection and after three steps, whether or not the process first stepped a box
  resting on a plane;
* a process whose first coal box query ran before the core was imported cannot import it
  (its contacts would silently depend on that query).
"""

from __future__ import annotations

import pickle
import subprocess
import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
FIELDS = ('body_a', 'body_b', 'point', 'normal', 'separation', 'toi', 'kind', 'feature',
          'manifolds')

# argv[1] 'plane': step a box resting on a plane once first; 'fresh': do not. Writes the
# pile's first contacts and its state after three steps, pickled, to stdout.
PILE = f'''
import pickle, sys
sys.path[:0] = [{str(HERE)!r}, {str(HERE.parents[1] / 'bench')!r}]
import numpy as np
from contacts import box, states
from integrator import Simulation
from pile import make_pile
from collres_ros.core.types import BodySpec
if sys.argv[1] == 'plane':
    floor = BodySpec('floor', 'plane', (0.0, 0.0, 1.0, 0.0), static=True)
    keep = Simulation([floor, box('box', (0.2,) * 3, 1.0)],
                      states([[0, 0, 0], [0, 0, 0.1]], np.zeros((2, 3))), 240.0)
    keep.step()
bodies, initial = make_pile(100, kind='cubes')
sim = Simulation(bodies, initial, 30.0)
current = sim.integrate(sim.state)
found = sim.world._collision.detect(sim.state, current, np.ones(current.count, bool))
out = {{k: np.asarray(getattr(found, k)) for k in {FIELDS!r}}}
for _ in range(3):
    sim.step()
out['position'] = np.asarray(sim.state.position)
out['orientation'] = np.asarray(sim.state.orientation)
sys.stdout.buffer.write(pickle.dumps(out))
'''


def _run(code: str, *args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, '-c', code, *args], capture_output=True,
                          timeout=300, cwd=HERE)


def _pile(mode: str) -> dict[str, np.ndarray]:
    run = _run(PILE, mode)
    assert run.returncode == 0, run.stderr.decode()[-2000:]
    return pickle.loads(run.stdout)


def test_a_pile_after_a_box_on_a_plane_equals_a_fresh_pile_byte_for_byte():
    fresh, after = _pile('fresh'), _pile('plane')
    assert fresh.keys() == after.keys()
    for key in fresh:
        a, b = fresh[key], after[key]
        assert a.shape == b.shape, (key, a.shape, b.shape)
        assert a.tobytes() == b.tobytes(), (
            key, float(np.abs(a.astype(float) - b.astype(float)).max()))


def test_the_core_warns_on_import_after_a_coal_box_query():
    """A coal box query made before the core is imported (a user's own coal use) fixes coal's
    box inflate for the process: the import says so with a RuntimeWarning and exposes the
    factor, and still works (a library user is never refused)."""
    run = _run('''
import coal, numpy as np
result = coal.CollisionResult()
coal.collide(coal.Box(1.0, 1.0, 1.0), coal.Transform3s(),
             coal.Halfspace(np.array([0.0, 0.0, 1.0]), 0.0), coal.Transform3s(),
             coal.CollisionRequest(), result)
from collres_ros.core import _native
print('inflate', *_native.BOX_SUPPORT_INFLATE)
''')
    assert run.returncode == 0, run.stderr
    assert b"RuntimeWarning: coal's box support was first called" in run.stderr
    inflate = [float(x) for x in run.stdout.split()[1:3]]
    assert inflate != [1.0, 1.0] and all(abs(x - 1.0) < 1e-9 for x in inflate)


def test_the_core_pins_the_exact_box_when_imported_first():
    run = _run('''
from collres_ros.core import _native
print('inflate', *_native.BOX_SUPPORT_INFLATE)
''')
    assert run.returncode == 0, run.stderr
    assert b'Warning' not in run.stderr
    assert [float(x) for x in run.stdout.split()[1:3]] == [1.0, 1.0]
