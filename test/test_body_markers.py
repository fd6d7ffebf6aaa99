"""body_markers read back from a recorded bag by an independent reader (mcap + mcap_ros2).

An offline run (as ``collres_sim --offline``) of spheres of two sizes, boxes, a
capsule, a static floor and a static triangle-mesh bin: every body_markers message must
show every body at that step's corrected pose (the static floor at its params pose),
with its size: a SPHERE_LIST per (diameter, static) group with the spheres'
centres, TRIANGLE_LISTs whose vertices, taken back to each body's frame,
span exactly the body's extents. Messages come at most every
``body_markers_period`` of stamp time. Then /tf's encoding against rosbags,
and the node's /tf over DDS.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

pytest.importorskip('rclpy')

from collres_ros.core.rotation import to_matrix  # noqa: E402
from collres_ros.ros import codec  # noqa: E402
from collres_ros.ros.body_markers import (  # noqa: E402
    MESHES_NS, SPHERES_NS, triangles)

SPHERE_LIST, TRIANGLE_LIST = 7, 11
RATE, PERIOD = 240.0, 0.05
BIN = Path(__file__).resolve().parent / 'data' / 'meshes' / 'bin.obj'
SCENE = f'''/**:
  ros__parameters:
    world_frame: world
    bodies: [floor, s1, s2, s3, b1, b2, cap, bin]
    body:
      floor: {{shape: box, size: [4.0, 4.0, 0.2], static: true, position: [0.0, 0.0, -0.1]}}
      s1: {{shape: sphere, size: [0.1], position: [0.0, 0.0, 0.3],
            linear_velocity: [0.5, 0.0, 0.0]}}
      s2: {{shape: sphere, size: [0.1], position: [0.5, 0.0, 0.5]}}
      s3: {{shape: sphere, size: [0.05], position: [-0.5, 0.0, 0.2]}}
      b1: {{shape: box, size: [0.2, 0.3, 0.4], position: [0.0, 0.8, 0.4],
            orientation: [0.0, 0.3826834, 0.0, 0.9238795], angular_velocity: [1.0, 2.0, 0.0]}}
      b2: {{shape: box, size: [0.1, 0.1, 0.1], position: [0.8, 0.8, 0.05]}}
      cap: {{shape: capsule, size: [0.05, 0.3], position: [-0.8, 0.5, 0.3],
             orientation: [0.7071068, 0.0, 0.0, 0.7071068]}}
      bin: {{shape: triangle_mesh, mesh: {BIN}, static: true, position: [1.5, -1.5, 0.0]}}
collres_node:
  ros__parameters:
    body_markers_period: {PERIOD}
collres_sim:
  ros__parameters:
    rate_hz: {RATE}
    duration: 0.6
'''


def _decoded(bag: Path, topics: list[str]) -> dict[str, dict[int, object]]:
    """{topic: {stamp ns: decoded message}} through mcap's own ROS 2 decoder."""
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory
    (file,) = bag.glob('*.mcap')
    out: dict[str, dict[int, object]] = {}
    with open(file, 'rb') as stream:
        reader = make_reader(stream, decoder_factories=[DecoderFactory()])
        for _, channel, _, decoded in reader.iter_decoded_messages(topics=topics):
            stamp = decoded.header.stamp if hasattr(decoded, 'header') \
                else decoded.markers[0].header.stamp
            out.setdefault(channel.topic, {})[stamp.sec * 10**9 + stamp.nanosec] = decoded
    return out


def test_body_markers_show_every_body_at_its_corrected_pose(tmp_path: Path) -> None:
    from collres_ros.ros.offline import run_offline
    from collres_ros.ros.simulation import load_sim_scene
    path = tmp_path / 'mixed.yaml'
    path.write_text(SCENE)
    sim = load_sim_scene(path)
    bodies = {b.name: b for b in sim.scene.bodies}
    params_pose = {n: np.concatenate([sim.scene.initial.position[i],
                                      sim.scene.initial.orientation[i]])
                   for i, n in enumerate(sim.names)}
    summary = run_offline(sim, tmp_path / 'bag')
    got = _decoded(tmp_path / 'bag', ['/body_markers', '/body_states/corrected'])
    markers, corrected = got['/body_markers'], got['/body_states/corrected']
    stamps = sorted(markers)
    gaps = np.diff(stamps) * 1e-9
    print(f'{len(stamps)} body_markers messages in {summary.steps} steps, gaps {set(gaps)}')
    assert len(stamps) >= 10
    assert (gaps >= PERIOD - 1e-9).all() and (gaps < PERIOD + 1.0 / RATE).all()
    moved = 0.0
    for stamp in stamps:
        pose = dict(params_pose)
        for b in corrected[stamp].bodies:
            p, q = b.pose.position, b.pose.orientation
            pose[b.name] = np.array([p.x, p.y, p.z, q.x, q.y, q.z, q.w])
        moved = max(moved, float(np.abs(pose['b1'][:3] - params_pose['b1'][:3]).max()))
        msg = markers[stamp]
        seen: set[str] = set()
        for m in msg.markers:
            assert m.header.frame_id == 'world' and m.action == 0
            points = np.array([(p.x, p.y, p.z) for p in m.points])
            if m.ns == SPHERES_NS:
                assert m.type == SPHERE_LIST
                group = [n for n, b in bodies.items()
                         if b.shape == 'sphere' and 2 * b.size[0] == pytest.approx(m.scale.x)]
                assert points == pytest.approx(np.array([pose[n][:3] for n in group]),
                                               abs=1e-12)
                seen.update(group)
                continue
            assert m.ns == MESHES_NS and m.type == TRIANGLE_LIST
            static = bool(m.id)
            start = 0
            for name, body in bodies.items():   # scene order, as the marker is built
                if body.shape == 'sphere' or body.static != static:
                    continue
                local = triangles(body)
                mine = points[start:start + len(local)]
                start += len(local)
                back = (mine - pose[name][:3]) @ to_matrix(pose[name][3:7])  # to the body frame
                assert back == pytest.approx(local, abs=1e-9), name
                if body.shape == 'box':
                    half = np.array(body.size) / 2
                    assert np.abs(back).max(0) == pytest.approx(half, abs=1e-12), name
                seen.add(name)
            assert start == len(points)
        assert seen == set(bodies), f'bodies missing from body_markers: {set(bodies) - seen}'
    assert moved > 0.01, 'the box never moved: the test would not see a stale pose'


def test_tf_message_encoding_reads_back_with_rosbags() -> None:
    from collres_ros.ros.bag import typestore
    store = typestore()
    rng = np.random.default_rng(3)
    names = ['floor', 'a', 'ball_2', 'x' * 37]
    poses = rng.normal(size=(len(names), 7))
    data = codec.encode_tf(1_234 * 10**9 + 56, 'world', codec.NamePool(names), poses)
    msg = store.deserialize_cdr(data, 'tf2_msgs/msg/TFMessage')
    assert [t.child_frame_id for t in msg.transforms] == names
    for t, row in zip(msg.transforms, poses):
        assert (t.header.frame_id, t.header.stamp.sec, t.header.stamp.nanosec) == \
            ('world', 1234, 56)
        tr, ro = t.transform.translation, t.transform.rotation
        assert [tr.x, tr.y, tr.z, ro.x, ro.y, ro.z, ro.w] == row.tolist()
    assert bytes(store.serialize_cdr(msg, 'tf2_msgs/msg/TFMessage')) == data


@pytest.mark.slow
def test_the_node_broadcasts_tf(ros_domain, tmp_path) -> None:
    """tf2_msgs: a ROS install's, or the one the build generates where it is missing."""
    from tf2_msgs.msg import TFMessage
    from ros_harness import Peer, write_scene

    from collres_ros.msg import BodyStateArray
    from collres_ros.ros import processes
    from test_node import T0, body, states
    scene = write_scene(tmp_path / 'scene.yaml', extra_node='    publish_tf: true\n')
    node = processes.start('collres_node', ['--ros-args', '--params-file', str(scene)],
                           env=processes.ros_env(ros_domain), log=tmp_path / 'node.log')
    peer = Peer(ros_domain)
    try:
        peer.listen('/tf', TFMessage)
        peer.advertise('body_states', BodyStateArray)
        assert peer.wait(lambda: peer.connected('body_states'), 30.0), node.output()
        for k in range(50):
            peer.publish('body_states', states(T0 + k * 10**7, [body('ball', 0.5),
                                                                body('box', 0.1, x=1.0)]))
            if peer.wait(lambda: peer.messages('/tf'), 0.2):
                break
        (msg, *_) = peer.messages('/tf')
        frames = {t.child_frame_id: t for t in msg.transforms}
        assert set(frames) == {'floor', 'ball', 'box'}
        assert frames['box'].header.frame_id == 'world'
        assert frames['box'].transform.translation.x == pytest.approx(1.0, abs=1e-3)
    finally:
        peer.close()
        if node.poll() is None:
            processes.stop(node)
