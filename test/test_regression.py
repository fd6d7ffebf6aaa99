"""Golden-bag regression: replaying each shipped input must give the golden output.

test/data/<scene>/input holds the states the node receives (``/body_states``)
and test/data/<scene>/golden the node's outputs for them
(``/body_states/corrected``, ``/contacts``), both written by
``tools/regenerate_goldens.py`` (``make goldens``), which also prints the
physical checks of each golden. The goldens are a net on top of the physics
tests, not a replacement.

Tolerances: positions 1e-6 m, orientations 1e-6, velocities 1e-6 m/s (rad/s),
contact points 1e-6 m, normals 1e-6, depths 1e-6 m, impulses 1e-6 N s; stamps,
body names and the contact set of each step (pairs and states) exactly equal.
The replay is deterministic on one machine; the tolerances absorb only
floating-point differences across numpy/coal builds.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

pytest.importorskip('rclpy')

DATA = Path(__file__).resolve().parent / 'data'
SCENES = Path(__file__).resolve().parent.parent / 'config' / 'scenes'
SHIPPED = sorted(p.name for p in DATA.iterdir() if (p / 'golden').is_dir()) \
    if DATA.is_dir() else []

TOLERANCE = {'position': 1e-6, 'orientation': 1e-6, 'linear': 1e-6, 'angular': 1e-6,
             'contact_position': 1e-6, 'normal': 1e-6, 'depth': 1e-6, 'impulse': 1e-6}


def _vec(v: Any) -> tuple[float, ...]:
    return tuple(getattr(v, a) for a in ('x', 'y', 'z', 'w') if hasattr(v, a))


def _close(a: Any, b: Any, tol: float) -> bool:
    return all(abs(x - y) <= tol for x, y in zip(_vec(a), _vec(b)))


def _diff_states(got: Any, want: Any) -> str | None:
    if [b.name for b in got.bodies] != [b.name for b in want.bodies]:
        return 'body names differ'
    for g, w in zip(got.bodies, want.bodies):
        for what, tol, a, b in (
                ('position', TOLERANCE['position'], g.pose.position, w.pose.position),
                ('orientation', TOLERANCE['orientation'], g.pose.orientation,
                 w.pose.orientation),
                ('linear', TOLERANCE['linear'], g.twist.linear, w.twist.linear),
                ('angular', TOLERANCE['angular'], g.twist.angular, w.twist.angular)):
            if not _close(a, b, tol):
                return f'{g.name} {what}: got {_vec(a)}, golden {_vec(b)} (tolerance {tol})'
    return None


def _contact_key(c: Any) -> tuple:
    return (c.body_a, c.body_b, c.state, round(c.position.x, 4), round(c.position.y, 4),
            round(c.position.z, 4))


def _diff_contacts(got: Any, want: Any) -> str | None:
    g_set = sorted((c.body_a, c.body_b, c.state) for c in got.contacts)
    w_set = sorted((c.body_a, c.body_b, c.state) for c in want.contacts)
    if g_set != w_set:
        return f'contact sets differ: got {g_set}, golden {w_set}'
    for g, w in zip(sorted(got.contacts, key=_contact_key),
                    sorted(want.contacts, key=_contact_key)):
        checks = (('position', TOLERANCE['contact_position'], g.position, w.position),
                  ('normal', TOLERANCE['normal'], g.normal, w.normal),
                  ('friction_impulse', TOLERANCE['impulse'], g.friction_impulse,
                   w.friction_impulse))
        for what, tol, a, b in checks:
            if not _close(a, b, tol):
                return f'{g.body_a}-{g.body_b} {what}: got {_vec(a)}, golden {_vec(b)}'
        if abs(g.normal_impulse - w.normal_impulse) > TOLERANCE['impulse']:
            return (f'{g.body_a}-{g.body_b} normal_impulse: got {g.normal_impulse}, '
                    f'golden {w.normal_impulse}')
        if abs(g.depth - w.depth) > TOLERANCE['depth']:
            return f'{g.body_a}-{g.body_b} depth: got {g.depth}, golden {w.depth}'
    return None


def first_difference(got: list, want: list) -> str | None:
    """A description of the first differing message of two output bags, or None."""
    from collres_ros.ros.bag import message_fields
    for topic, differ in (('/body_states/corrected', _diff_states),
                          ('/contacts', _diff_contacts)):
        g = [m for m in got if m.topic == topic]
        w = [m for m in want if m.topic == topic]
        if len(g) != len(w):
            return f'{topic}: {len(g)} messages, golden has {len(w)}'
        for k, (a, b) in enumerate(zip(g, w)):
            if (a.msg.header.stamp.sec, a.msg.header.stamp.nanosec) != \
                    (b.msg.header.stamp.sec, b.msg.header.stamp.nanosec) \
                    or a.log_time != b.log_time:
                return f'{topic} #{k}: stamp or log time differs'
            why = differ(a.msg, b.msg)
            if why is not None:
                return (f'{topic} message #{k} (log time {a.log_time} ns): {why}\n'
                        f'  replayed: {message_fields(a.msg)}\n'
                        f'  golden:   {message_fields(b.msg)}')
    return None


def test_every_shipped_scene_has_a_golden() -> None:
    scenes = sorted(p.stem for p in SCENES.glob('*.yaml'))
    assert scenes, 'no scenes shipped'
    assert SHIPPED == scenes, f'goldens {SHIPPED} vs scenes {scenes}: run make goldens'


def test_goldens_are_small() -> None:
    total = sum(f.stat().st_size for f in DATA.rglob('*') if f.is_file())
    print(f'test/data: {total / 1024:.1f} KiB')
    assert total < 2 * 1024 * 1024


@pytest.mark.parametrize('scene', SHIPPED)
def test_replay_matches_golden(tmp_path: Path, scene: str) -> None:
    from collres_ros.ros.bag import read_messages
    from collres_ros.ros.offline import replay
    summary = replay(DATA / scene / 'input', tmp_path / 'out', SCENES / f'{scene}.yaml',
                     topics=('body_states/corrected', 'contacts'))
    golden = read_messages(DATA / scene / 'golden')
    replayed = read_messages(tmp_path / 'out')
    assert summary.steps > 0 and golden, 'nothing was replayed'
    assert summary.steps == len([m for m in golden if m.topic == '/body_states/corrected'])
    difference = first_difference(replayed, golden)
    assert difference is None, difference


def test_a_difference_is_reported_with_both_values() -> None:
    """The regression check is not vacuous: a 1e-5 m change is caught and shown."""
    import copy

    from collres_ros.ros.bag import read_messages
    scene = 'bouncing_ball' if 'bouncing_ball' in SHIPPED else SHIPPED[0]
    golden = read_messages(DATA / scene / 'golden')
    assert first_difference(golden, golden) is None
    changed = copy.deepcopy(golden)
    k = len(changed) // 2
    while changed[k].topic != '/body_states/corrected':
        k += 1
    changed[k].msg.bodies[0].pose.position.z += 1e-5
    why = first_difference(changed, golden)
    assert why is not None and 'position' in why
    assert 'replayed:' in why and 'golden:' in why
    print(why.splitlines()[0])


@pytest.mark.parametrize('scene', SHIPPED)
def test_shipped_bags_open_with_rosbags_and_the_mcap_reader(scene: str) -> None:
    """Independent readers decode every message (custom types via embedded definitions)."""
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory
    from rosbags.rosbag2 import Reader
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore
    for part in ('input', 'golden'):
        path = DATA / scene / part
        with Reader(path) as reader:
            # a typestore that knows only what the bag itself embeds
            store = get_typestore(Stores.EMPTY)
            for connection in reader.connections:
                store.register(get_types_from_msg(connection.msgdef.data, connection.msgtype))
            count = sum(1 for c, _, data in reader.messages()
                        if store.deserialize_cdr(data, c.msgtype) is not None)
            assert count == reader.message_count > 0
        (file,) = path.glob('*.mcap')
        with open(file, 'rb') as stream:
            decoded = list(make_reader(stream, decoder_factories=[DecoderFactory()])
                           .iter_decoded_messages())
        assert len(decoded) == count
        assert {schema.name for schema, _, _, _ in decoded} <= {
            'collres_ros/msg/BodyStateArray', 'collres_ros/msg/ContactArray'}
