"""contact_markers read back from a recorded bag by an independent reader (mcap + mcap_ros2).

Each step's MarkerArray must show exactly that step's contacts: eleven markers
(DELETEALL, then a SPHERE_LIST of points and a LINE_LIST of normals per
contact state, or DELETEs for a state without contacts), the points equal to
the contacts' positions, the normals along the contacts' normals, the colours
those of the README's table.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

pytest.importorskip('rclpy')

from collres_ros.ros.markers import (  # noqa: E402
    NORMAL_MAX, NORMAL_MIN, NORMAL_PER_IMPULSE, STATE_COLOURS)
from collres_ros.ros.offline import run_offline  # noqa: E402
from collres_ros.ros.simulation import load_sim_scene  # noqa: E402

SCENES = Path(__file__).resolve().parent.parent / 'config' / 'scenes'
SPHERE_LIST, LINE_LIST, DELETE, DELETEALL = 7, 5, 2, 3


def _decoded(bag: Path) -> dict[str, dict[int, object]]:
    """{topic: {log time: decoded message}} through mcap's own ROS 2 decoder."""
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory
    (file,) = bag.glob('*.mcap')
    out: dict[str, dict[int, object]] = {}
    with open(file, 'rb') as stream:
        reader = make_reader(stream, decoder_factories=[DecoderFactory()])
        for _, channel, message, decoded in reader.iter_decoded_messages(
                topics=['/contacts', '/contact_markers']):
            out.setdefault(channel.topic, {})[message.log_time] = decoded
    return out


def _xyz(v) -> list[float]:
    return [v.x, v.y, v.z]


@pytest.mark.parametrize('scene, duration', [('bouncing_ball', 0.8), ('slope_slide', 0.4),
                                             ('slope_hold', 2.5)])
def test_markers_show_the_contacts_of_their_step(tmp_path: Path, scene: str,
                                                 duration: float) -> None:
    run_offline(load_sim_scene(SCENES / f'{scene}.yaml', duration), tmp_path / 'bag')
    messages = _decoded(tmp_path / 'bag')
    contacts, markers = messages['/contacts'], messages['/contact_markers']
    assert sorted(contacts) == sorted(markers) and contacts
    seen_states, empty_steps = set(), 0
    for log_time, array in markers.items():
        step = contacts[log_time]
        assert array.markers[0].action == DELETEALL
        assert len(array.markers) == 1 + 2 * len(STATE_COLOURS) == 11, \
            'the number of markers must not depend on contacts'
        empty_steps += not step.contacts
        shown = {(m.ns, m.id): m for m in array.markers[1:]}
        assert len(shown) == 10
        for state, colour in STATE_COLOURS.items():
            mine = [c for c in step.contacts if c.state == int(state)]
            points, normals = shown[('contact_points', int(state))], \
                shown[('contact_normals', int(state))]
            if not mine:
                assert points.action == normals.action == DELETE
                continue
            seen_states.add(state.name)
            assert (points.type, normals.type) == (SPHERE_LIST, LINE_LIST)
            for m in (points, normals):
                assert m.header.frame_id == step.header.frame_id
                assert (m.header.stamp.sec, m.header.stamp.nanosec) == \
                    (step.header.stamp.sec, step.header.stamp.nanosec)
                assert [m.color.r, m.color.g, m.color.b, m.color.a] == \
                    pytest.approx(list(colour), abs=1e-6)
            np.testing.assert_array_equal([_xyz(p) for p in points.points],
                                          [_xyz(c.position) for c in mine])
            segments = np.array([_xyz(p) for p in normals.points]).reshape(-1, 2, 3)
            np.testing.assert_array_equal(segments[:, 0], [_xyz(c.position) for c in mine])
            length = np.minimum(NORMAL_MIN + NORMAL_PER_IMPULSE * np.array(
                [c.normal_impulse for c in mine]), NORMAL_MAX)
            np.testing.assert_allclose(segments[:, 1] - segments[:, 0],
                                       length[:, None] * [_xyz(c.normal) for c in mine],
                                       atol=1e-12)
    print(scene, 'states shown:', sorted(seen_states), 'steps without contacts:', empty_steps)
    assert seen_states, 'no contact was ever shown: the check would be vacuous'
    if scene == 'bouncing_ball':
        assert empty_steps > 0   # in flight: every state's markers deleted
    if scene == 'slope_hold':    # the box held on the slope falls asleep: grey contacts
        assert 'SLEEPING' in seen_states and 'STICKING' in seen_states
