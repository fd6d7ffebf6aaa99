"""collres_node's /diagnostics say whether the second thread took part (``threads`` 2):
the runs posted for two threads and those run paired (since start), and over each period
the share of them run paired and the share of their chunks the second thread ran."""

from __future__ import annotations

import pytest
from ros_harness import node_and_peer
from test_node import DT, T0, body, diagnostics_values, step

from collres_ros.msg import BodyStateArray

pytestmark = pytest.mark.slow
GRID = 9   # boxes a side: 81 boxes and the floor, over detection's 64 shapes to share


def boxes_scene(path):
    """A floor and GRID x GRID boxes of 0.2 m resting on it, 0.3 m apart (four contacts
    each: 324, enough for the solver's passes in two threads' parts); sleeping off, so
    every step detects and solves."""
    names = [f'b{k}' for k in range(GRID * GRID)]
    lines = ['/**:', '  ros__parameters:', '    world_frame: world',
             f'    bodies: [floor, {", ".join(names)}]', '    body:',
             '      floor: {shape: box, size: [10.0, 10.0, 0.2], static: true, '
             'position: [0.0, 0.0, -0.1]}']
    lines += [f'      {name}: {{shape: box, size: [0.2, 0.2, 0.2], '
              f'position: [{0.3 * (k % GRID)}, {0.3 * (k // GRID)}, 0.1]}}'
              for k, name in enumerate(names)]
    lines += ['    solver: {sleeping: false}', 'collres_node:', '  ros__parameters:',
              '    diagnostics_period: 0.1']
    path.write_text('\n'.join(lines) + '\n')
    return path, names


def at_rest(names):
    """The boxes as an estimator measures them at rest: their poses, zero twists."""
    bodies = [body(name, 0.1, x=0.3 * (k % GRID)) for k, name in enumerate(names)]
    for k, b in enumerate(bodies):
        b.pose.position.y = 0.3 * (k // GRID)
    return bodies


def report_after(peer, steps):
    """The values of a /diagnostics report that counts ``steps`` steps (the last ones
    stepped: every answer was received before)."""
    assert peer.wait(lambda: int(diagnostics_values(peer).get('steps', -1)) >= steps, 10.0)
    return diagnostics_values(peer)


def test_diagnostics_say_whether_the_second_thread_took_part(ros_domain, tmp_path):
    scene, names = boxes_scene(tmp_path / 'boxes.yaml')
    with node_and_peer(ros_domain, scene, tmp_path / 'node.log',
                       listen=(('body_states/corrected', BodyStateArray),)) as (peer, node):
        # steps until a report's period held some (reports every 0.1 s): 20 at least
        shares, k = [], 0
        while k < 20 or not shares and k < 500:
            out = step(peer, T0 + k * DT, at_rest(names))
            assert len(out.bodies) == len(names)
            k += 1
            values = diagnostics_values(peer)
            if values.get('threads.paired_share', 'n/a') != 'n/a':
                shares.append((float(values['threads.paired_share']),
                               float(values['threads.second_share'])))
        values = report_after(peer, k)
        print(k, 'steps:', {key: v for key, v in values.items() if key.startswith('threads')})
        runs, paired = int(values['threads.runs']), int(values['threads.paired_runs'])
        assert values['threads'] == '2'
        # every step posts a detect and the solve's passes for two threads; the cost model
        # runs each kind of run paired first (no mode measured yet)
        assert runs >= k and 1 <= paired <= runs
        assert shares and all(0.0 <= s <= 1.0 and 0.0 <= h <= 1.0 for s, h in shares)
        assert node.poll() is None
