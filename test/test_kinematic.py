"""Kinematic bodies: static (infinite mass) bodies that collres_sim moves at a prescribed twist.

The scenes (test/scenes/) run offline through the core, as ``collres_sim
--offline`` does: the sim integrates the belt / table at its twist and
publishes it with the dynamic box, the core treats the static body's twist
as its velocity, friction does the rest.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from collres_ros.core.types import BodyStates
from collres_ros.ros.integrator import euler_step

SCENES = Path(__file__).resolve().parent / 'scenes'
G = 9.81


def run(scene: str | Path) -> tuple[np.ndarray, dict[str, dict[str, np.ndarray]], list[list]]:
    """(t s, {body: {position, orientation, linear, angular} (T, k)}, contacts per step)."""
    pytest.importorskip('rclpy')
    from collres_ros.ros.offline import run_core
    from collres_ros.ros.simulation import load_sim_scene
    sim = load_sim_scene(scene if isinstance(scene, Path) else SCENES / f'{scene}.yaml')
    stamps: list[int] = []
    rows: dict[str, dict[str, list]] = {}
    contacts: list[list] = []

    from rclpy.serialization import deserialize_message

    from collres_ros.ros.bag import message_class

    def sink(stamp: int, outputs: list) -> None:   # (topic, wire type, CDR bytes)
        out = {topic: deserialize_message(data, message_class(kind))
               for topic, kind, data in outputs}
        stamps.append(stamp)
        for body in out['body_states/corrected'].bodies:
            fields = ('position', 'orientation', 'linear', 'angular')
            row = rows.setdefault(body.name, {k: [] for k in fields})
            p, q, v, w = body.pose.position, body.pose.orientation, body.twist.linear, \
                body.twist.angular
            row['position'].append((p.x, p.y, p.z))
            row['orientation'].append((q.x, q.y, q.z, q.w))
            row['linear'].append((v.x, v.y, v.z))
            row['angular'].append((w.x, w.y, w.z))
        contacts.append(list(out['contacts'].contacts))

    run_core(sim, sink, markers=False)
    t = (np.array(stamps) - stamps[0]) * 1e-9
    return t, {n: {k: np.array(v) for k, v in r.items()} for n, r in rows.items()}, contacts


def test_the_integrator_moves_kinematic_bodies_at_their_twist_without_gravity() -> None:
    states = BodyStates.zeros(3)
    states.linear[:] = (1.0, 0.0, 0.0)
    states.angular[:] = (0.0, 0.0, np.pi)
    dynamic, kinematic = np.array([True, False, False]), np.array([False, True, False])
    g, dt, n = np.array([0.0, 0.0, -G]), 0.01, 50
    for _ in range(n):
        states = euler_step(states, dynamic, g, dt, kinematic)
    # the kinematic body: x = v t, a quarter turn after 0.5 s, its twist unchanged
    assert states.position[1] == pytest.approx([0.5, 0.0, 0.0], abs=1e-12)
    assert states.orientation[1] == pytest.approx([0, 0, np.sin(np.pi / 4), np.cos(np.pi / 4)],
                                                  abs=1e-12)
    assert states.linear[1] == pytest.approx([1.0, 0.0, 0.0]) and states.angular[1, 2] == np.pi
    # the dynamic body falls, the plain static body stays put with zero twist
    assert states.linear[0, 2] == pytest.approx(-G * n * dt)
    assert not states.position[2].any() and not states.linear[2].any()


def test_a_kinematic_body_is_static_and_published_but_never_adopted() -> None:
    pytest.importorskip('rclpy')
    from collres_ros.ros.messages import body_state_array, read_body_state_array
    from collres_ros.ros.simulation import adopt, load_sim_scene, rows_of
    sim = load_sim_scene(SCENES / 'conveyor.yaml')
    belt = sim.names.index('belt')
    assert sim.scene.bodies[belt].static and sim.scene.kinematic[belt]
    assert not sim.dynamic[belt] and belt in sim.rows
    published = [sim.names[i] for i in sim.rows]
    msg = body_state_array(published, rows_of(sim.initial, sim.rows), 10**9, sim.world_frame)
    assert [b.name for b in msg.bodies] == ['belt', 'box']
    assert msg.bodies[0].twist.linear.x == 1.0
    msg.bodies[0].pose.position.x = 99.0        # a corrected state never moves the belt
    msg.bodies[1].pose.position.x = 7.0
    adopted = adopt(sim.initial, sim.names, *read_body_state_array(msg), sim.dynamic)
    assert adopted.position[belt, 0] == 0.0 and adopted.position[sim.names.index('box'), 0] == 7.0


@pytest.mark.parametrize('release', [
    'dropped', 'placed'])
def test_a_box_on_a_belt_reaches_the_belt_speed_and_then_rides_with_it(
        tmp_path: Path, release: str) -> None:
    """Dropped from 5 cm, or placed on the belt at rest: slides at mu_k g, then held."""
    scene = SCENES / 'conveyor.yaml'
    if release == 'placed':
        scene = tmp_path / 'placed.yaml'
        text = (SCENES / 'conveyor.yaml').read_text()
        assert 'position: [0.0, 0.0, 0.15]' in text
        scene.write_text(text.replace('position: [0.0, 0.0, 0.15]', 'position: [0.0, 0.0, 0.1]'))
    t, states, contacts = run(scene)
    belt, box = states['belt'], states['box']
    speed = 1.0
    mu_k = 0.4
    # the belt moves at its prescribed speed: x = v t
    assert belt['position'][:, 0] == pytest.approx(speed * t, abs=1e-9)
    assert belt['linear'][:, 0] == pytest.approx(np.full(len(t), speed))
    first = next(k for k, c in enumerate(contacts) if c)
    rebound = float(box['linear'][first:, 2].max())
    print(f'largest upward speed after the first contact {rebound:.4f} m/s (restitution 0)')
    assert rebound < 0.05, 'a restitution-0 box rebounded'
    slip = speed - box['linear'][:, 0]
    reached = int(np.argmax(np.abs(slip) < 1e-3))
    # placed: mu_k g from the start; dropped: the impact's friction impulse mu_k m g t_fall,
    # then mu_k g while sliding: either way the belt speed is reached v / (mu_k g) after
    # the release (the fall, 0.1 s, is shorter)
    expected = speed / (mu_k * G)
    print(f'belt speed reached after {t[reached]:.4f} s, expected v / (mu_k g) = '
          f'{expected:.4f} s')
    assert reached > 0, 'the box never reached the belt speed'
    assert t[reached] == pytest.approx(expected, rel=0.05)
    sliding = [c for k in range(reached) for c in contacts[k]
               if c.state == c.SLIDING and np.hypot(c.friction_impulse.x, c.friction_impulse.y)]
    assert sliding, 'no sliding contact with a friction impulse before the speed was reached'
    # then static friction holds: same speed, same place on the belt, still on top of it
    after = t >= t[reached] + 0.1
    offset = box['position'][after, 0] - belt['position'][after, 0]
    print(f'after: box speed {box["linear"][after, 0].min():.6f}..'
          f'{box["linear"][after, 0].max():.6f} m/s (belt {speed}), place on the belt '
          f'drifts {1000 * np.ptp(offset):.4f} mm over {t[after][-1] - t[after][0]:.2f} s, '
          f'height {box["position"][after, 2].min():.5f}..{box["position"][after, 2].max():.5f} m')
    assert np.abs(box['linear'][after, 0] - speed).max() < 1e-3
    assert np.ptp(offset) < 1e-3
    assert np.abs(box['position'][after, 2] - 0.1).max() < 2e-3
    assert np.abs(box['position'][:, 1]).max() < 1e-6
    assert all(contacts[k] for k in np.flatnonzero(after)), 'the box left the belt'


def _yaw(q: np.ndarray) -> np.ndarray:
    x, y, z, w = q.T
    return np.unwrap(np.arctan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z)))


def test_a_box_on_a_turntable_turns_with_it() -> None:
    t, states, contacts = run('turntable')
    table, box = states['table'], states['box']
    omega, radius = 1.0, 0.5
    # the table turns at its prescribed rate about its fixed axis
    assert _yaw(table['orientation']) == pytest.approx(omega * t, abs=1e-6)
    assert np.abs(table['position'] - table['position'][0]).max() == 0.0
    polar = np.unwrap(np.arctan2(box['position'][:, 1], box['position'][:, 0]))
    r = np.hypot(box['position'][:, 0], box['position'][:, 1])
    held = t >= 1.0
    lag = omega * t[held] - polar[held]         # the box's angle behind the table's
    spin_lag = _yaw(table['orientation'])[held] - _yaw(box['orientation'])[held]
    speed = np.linalg.norm(box['linear'][held, :2], axis=1)
    print(f'after 1 s: lag behind the table {lag.min():.5f}..{lag.max():.5f} rad, radius '
          f'{r[held].min():.5f}..{r[held].max():.5f} m (started {radius}), speed '
          f'{speed.min():.5f}..{speed.max():.5f} m/s (w r = {omega * radius}), box spin '
          f'{box["angular"][held, 2].min():.6f}..{box["angular"][held, 2].max():.6f} rad/s')
    assert polar[-1] > 2.5, 'the box did not go round'
    assert np.ptp(lag) < 0.01 and np.ptp(spin_lag) < 0.01
    assert np.abs(r[held] - radius).max() < 5e-3
    assert speed == pytest.approx(np.full(len(speed), omega * radius), rel=0.02)
    assert box['angular'][held, 2] == pytest.approx(np.full(held.sum(), omega), abs=1e-3)
    states_seen = {c.state for k in np.flatnonzero(held) for c in contacts[k]}
    assert states_seen and states_seen <= {2, 4}, states_seen   # RESTING / STICKING: held
