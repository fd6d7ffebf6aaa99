"""Convex vertex sets no hull can be built of: one error line naming the parameter, never a
crash.

qhull (under coal) reports a flat, coplanar, collinear or coincident set
through an error stream coal leaves unset, and the process dies (SIGSEGV, no
line). Every hull is built only after the compiled core's check
(``_native.hull_problem``), which the params validator, the Python shapes and
the compiled Detector all use. The crashing cases run in a child process, so a
crash fails the test instead of ending the run.
"""

from __future__ import annotations

import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

from collres_ros.core import _native
from collres_ros.core.shapes import convex_points
from collres_ros.core.types import BodySpec
from collres_ros.ros import params, processes

ROOT = Path(__file__).resolve().parents[1]
SQUARE = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [1.0, 1.0, 0.0]]
# each passed both validators before (params rank test, shapes.convex_points at 1e-9)
UNBUILDABLE = {
    'nearly flat': SQUARE + [[0.5, 0.5, 1e-8]],        # a 1 m square, apex 10 nm above it
    'coplanar': SQUARE + [[0.5, 0.25, 0.0]],
    'duplicates': [[0.3, 0.3, 0.3]] * 6,
    'collinear': [[float(k), 0.0, 0.0] for k in range(5)],
    'three points': SQUARE[:3],
}


def scene_text(points: list[list[float]]) -> str:
    flat = ', '.join(repr(c) for p in points for c in p)
    return textwrap.dedent(f'''\
        /**:
          ros__parameters:
            bodies: [floor, ball]
            body:
              floor: {{shape: box, size: [4.0, 4.0, 0.2], static: true,
                      position: [0.0, 0.0, -0.1]}}
              ball: {{shape: convex, points: [{flat}], position: [0.0, 0.0, 0.5]}}
        collres_sim:
          ros__parameters: {{duration: 0.05}}
        ''')


def run(script: str, args: list[str], cwd: Path) -> subprocess.CompletedProcess:
    result = subprocess.run(processes.command(script) + args, capture_output=True, text=True,
                            timeout=120, cwd=cwd, env=processes.ros_env())
    print(script, result.returncode, repr(result.stdout[-300:]), repr(result.stderr[-600:]))
    return result


@pytest.mark.parametrize('case', sorted(UNBUILDABLE))
def test_the_validator_refuses_what_no_hull_can_be_built_of(case: str) -> None:
    values = {'bodies': ['ball'], 'body.ball.shape': 'convex',
              'body.ball.points': [c for p in UNBUILDABLE[case] for c in p]}
    with pytest.raises(ValueError) as info:
        params.scene_from_values(values)
    print(info.value)
    assert str(info.value).startswith('body.ball.points: convex needs at least 4 points '
                                      'spanning a volume')
    with pytest.raises(ValueError, match='^ball: convex '):
        convex_points(BodySpec('ball', 'convex', points=tuple(map(tuple, UNBUILDABLE[case]))))


def test_the_threshold_has_a_margin_over_where_qhull_fails() -> None:
    # measured: an apex 1e-8 of the extent kills qhull, 3e-8 does not; refused up to 1e-6
    for height in (1e-8, 1e-7, 1e-6):
        assert 'one plane' in _native.hull_problem(sum(SQUARE + [[0.5, 0.5, height]], []))
    for height in (2e-6, 1e-3, 1.0):
        assert _native.hull_problem(sum(SQUARE + [[0.5, 0.5, height]], [])) == ''


def test_the_tools_give_one_line_not_a_crash(tmp_path: Path) -> None:
    good = tmp_path / 'good.yaml'
    good.write_text(scene_text(SQUARE + [[0.5, 0.5, 0.5]]))
    bag = tmp_path / 'bag'
    assert run('collres_sim', ['--offline', '--params', str(good), '--record', str(bag)],
               tmp_path).returncode == 0
    flat = tmp_path / 'flat.yaml'
    flat.write_text(scene_text(UNBUILDABLE['nearly flat']))
    for script, args in (
            ('collres_sim', ['--offline', '--params', str(flat), '--record', str(tmp_path / 'o')]),
            ('collres_replay', [str(bag), str(tmp_path / 'out'), '--params', str(flat)]),
            ('collres_node', ['--ros-args', '--params-file', str(flat)])):
        result = run(script, args, tmp_path)
        lines = result.stderr.strip().splitlines()
        assert result.returncode == 1, f'{script}: rc {result.returncode}'
        assert len(lines) == 1 and 'body.ball.points' in lines[0] and 'one plane' in lines[0]


FUZZ = '''
import sys
import numpy as np
from collres_ros.core import _native
rng = np.random.default_rng(20260)
built = refused = 0
for case in range(int(sys.argv[1])):
    family = case % 6
    count = int(rng.integers(0, 24))
    points = np.c_[rng.uniform(0, 1, (count, 2)), np.zeros(count)]
    if family == 0 and count:
        points[-1, 2] = 10.0 ** rng.uniform(-14, 0)      # nearly flat
    elif family == 1:
        points[:, 1] = 0.0                                # collinear
    elif family == 2:
        points[:] = 0.25                                  # one spot
    elif family == 3:
        points[:, 2] = rng.uniform(0, 1, count)           # a volume
    elif family == 4 and count:
        points.flat[rng.integers(0, points.size)] = rng.choice([np.nan, np.inf, 1e300])
    turn = np.linalg.qr(rng.normal(size=(3, 3)))[0]
    scale = 10.0 ** rng.uniform(-6, 6)
    points = points @ turn.T * scale + rng.uniform(-1, 1, 3) * scale * rng.choice([0, 1, 50])
    flat = points.reshape(-1).tolist()
    if family == 5 and flat:
        flat = flat[:-1]                                  # not triples
    kind = 6 if case % 7 else int(rng.integers(-2, 9))
    size = [float(v) for v in rng.choice([-1.0, 0.0, np.nan, np.inf, 0.5, 1e300], 4)]
    try:
        _native.Detector([kind], [size], [flat], [float(scale)], [False])
        built += 1
    except ValueError:
        refused += 1
print(built, refused)
'''


def test_native_never_crashes_on_hostile_shapes() -> None:
    result = subprocess.run([sys.executable, '-c', FUZZ, '600'], capture_output=True,
                            text=True, timeout=300)
    print(result.returncode, result.stdout, result.stderr[-2000:])
    assert result.returncode == 0, 'the compiled core died on a shape'
    built, refused = map(int, result.stdout.split())
    assert built > 50 and refused > 200   # both roads taken


def test_hull_problem_holds_for_random_volumes() -> None:
    rng = np.random.default_rng(7)
    for _ in range(200):
        points = rng.normal(size=(int(rng.integers(4, 30)), 3)) * 10.0 ** rng.uniform(-5, 5)
        assert _native.hull_problem(points.reshape(-1).tolist()) == ''
