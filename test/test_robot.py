"""robot_description (URDF) in: one kinematic compound body per link with collisions, one
piece per collision element at its origin, meshes found by package:// and file://, link
pairs that never collide, and one-line errors naming the link."""

from __future__ import annotations

import math
import shutil
from pathlib import Path

import numpy as np
import pytest

from collres_ros.core.rotation import to_matrix
from collres_ros.core.shapes import load_mesh_points
from collres_ros.core.types import COMPOUND
from collres_ros.ros import params
from collres_ros.ros.robot import quaternion_of_rpy

SCENES = Path(__file__).resolve().parents[1] / 'config' / 'scenes'
MESHES = SCENES / 'meshes'   # the arm's finger mesh


def arm_urdf(meshes: str = 'package://collres_test_robot/meshes') -> str:
    """The test arm: the URDF of the shipped arm scene (config/scenes/arm.yaml; several
    collision elements per link, one mesh scaled, one link without collisions), its finger
    mesh found under ``meshes`` (a package:// or file:// folder)."""
    import yaml
    scene = yaml.safe_load((SCENES / 'arm.yaml').read_text())
    return scene['/**']['ros__parameters']['robot_description'].replace(
        'filename="meshes/', f'filename="{meshes}/')


URDF = arm_urdf()
LINKS = ['base_link', 'upper_arm', 'forearm', 'hand']


@pytest.fixture
def package(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """An ament prefix holding the package collres_test_robot (its meshes)."""
    index = tmp_path / 'prefix' / 'share' / 'ament_index' / 'resource_index' / 'packages'
    index.mkdir(parents=True)
    (index / 'collres_test_robot').write_text('')
    shutil.copytree(MESHES, tmp_path / 'prefix' / 'share' / 'collres_test_robot' / 'meshes')
    monkeypatch.setenv('AMENT_PREFIX_PATH', str(tmp_path / 'prefix'))
    return tmp_path / 'prefix' / 'share' / 'collres_test_robot'


def scene(**values):
    return params.scene_from_values({'bodies': ['box'], 'body.box.shape': 'box',
                                     'body.box.size': [0.1, 0.1, 0.1],
                                     'robot_description': URDF, **values})


def test_every_link_with_collisions_is_a_kinematic_compound(package) -> None:
    loaded = scene()
    assert loaded.names == ['box', *LINKS]    # tool0 has no collision: no body
    links = {b.name: b for b in loaded.bodies[1:]}
    assert all(b.shape == COMPOUND and b.static for b in links.values())
    assert all(loaded.values[f'body.{name}.kinematic'] for name in LINKS)
    base = links['base_link'].pieces
    assert [(p.name, p.shape, p.size, p.position) for p in base] == [
        ('pedestal', 'cylinder', (0.1, 0.05), (0.0, 0.0, 0.025)),
        ('plate', 'box', (0.3, 0.3, 0.01), (0.0, 0.0, 0.005))]
    upper = links['upper_arm'].pieces   # unnamed elements: collision_<k>
    assert [(p.name, p.shape) for p in upper] == [('collision_0', 'box'),
                                                  ('collision_1', 'sphere')]
    tube = links['forearm'].pieces[0]   # rpy (0, pi/2, 0) turns the cylinder's z onto x
    np.testing.assert_allclose(to_matrix(np.array(tube.orientation)) @ [0, 0, 1], [1, 0, 0],
                               atol=1e-15)
    finger = links['hand'].pieces[1]    # the mesh's hull, scaled by (0.5, 1, 1)
    expected = load_mesh_points(str(MESHES / 'finger.stl')) * [0.5, 1.0, 1.0]
    assert finger.shape == 'convex'
    assert sorted(finger.points) == sorted(tuple(p) for p in expected.tolist())


def test_links_never_collide_with_one_another_unless_asked(package) -> None:
    names = scene().names
    idx = {n: names.index(n) for n in names}
    default = scene().collision_filter
    assert not any(default.collides(idx[a], idx[b]) for a in LINKS for b in LINKS if a != b)
    assert all(default.collides(idx['box'], idx[link]) for link in LINKS)
    chosen = scene(robot_self_collision=True).collision_filter
    adjacent = {('base_link', 'upper_arm'), ('upper_arm', 'forearm'), ('forearm', 'hand')}
    for i, a in enumerate(LINKS):
        for b in LINKS[i + 1:]:
            assert chosen.collides(idx[a], idx[b]) == ((a, b) not in adjacent), (a, b)


def test_a_links_materials_may_be_set_and_the_recorded_scene_needs_no_urdf(package) -> None:
    loaded = scene(**{'body.hand.restitution': 0.1})
    assert loaded.bodies[LINKS.index('hand') + 1].restitution == 0.1
    recorded = params.load_recorded_scene(params.scene_to_yaml(loaded), 'bag')
    assert recorded.bodies == loaded.bodies
    assert recorded.collision_filter == loaded.collision_filter


def test_file_urls_are_read_and_unusable_links_are_named(package, tmp_path) -> None:
    by_file = URDF.replace('package://collres_test_robot', f'file://{package}')
    assert scene(robot_description=by_file).bodies == scene().bodies
    cases = [
        (URDF.replace('collres_test_robot', 'no_such_package'),
         r"^robot_description: link 'hand': collision 1: cannot read mesh "
         r"'package://no_such_package/meshes/finger\.stl' \(.*package 'no_such_package' not "
         r"found"),
        (URDF.replace('finger.stl', 'finger.dae'),
         r"^robot_description: link 'hand': collision 1: cannot read mesh .*finger\.dae"),
        (URDF.replace('<link name="forearm">', '<link name="fore-arm">').replace(
            '<child link="forearm"/>', '<child link="fore-arm"/>').replace(
            '<parent link="forearm"/>', '<parent link="fore-arm"/>'),
         r"^robot_description: link 'fore-arm': a link with collisions must be named as a "
         r"body"),
        ('<robot name="x"><link name="a">', r'^robot_description: not a URDF'),
        (URDF.replace('<sphere radius="0.04"/>', '<sphere radius="-0.04"/>'),
         r'^body\.upper_arm\.piece\.collision_1\.size: sphere needs 1 values \[r\] > 0'),
    ]
    for text, message in cases:
        with pytest.raises(ValueError, match=message):
            scene(robot_description=text)
    with pytest.raises(ValueError, match=r"^bodies: 'hand' is also a link"):
        scene(bodies=['hand'], **{'body.hand.shape': 'box'})


@pytest.mark.parametrize('rpy', [(0.3, 0.0, 0.0), (0.0, -0.7, 0.0), (0.0, 0.0, 2.0),
                                 (0.4, -1.1, 2.5)])
def test_rpy_is_fixed_axis_roll_then_pitch_then_yaw(rpy) -> None:
    r, p, y = rpy
    rx = np.array([[1, 0, 0], [0, math.cos(r), -math.sin(r)], [0, math.sin(r), math.cos(r)]])
    ry = np.array([[math.cos(p), 0, math.sin(p)], [0, 1, 0], [-math.sin(p), 0, math.cos(p)]])
    rz = np.array([[math.cos(y), -math.sin(y), 0], [math.sin(y), math.cos(y), 0], [0, 0, 1]])
    np.testing.assert_allclose(to_matrix(np.array(quaternion_of_rpy(*rpy))), rz @ ry @ rx,
                               atol=1e-15)


def test_link_poses_follow_the_joints() -> None:
    """Forward kinematics of the test arm: shoulder 0.05 m above the base, elbow 0.3 m up
    the upper arm, the wrist 0.25 m along the forearm's x; turning the shoulder by pi/2
    about y lays the arm along +x."""
    from collres_ros.ros.robot import link_poses
    upright = link_poses(URDF)
    np.testing.assert_allclose(upright['upper_arm'][0], [0, 0, 0.05], atol=1e-15)
    np.testing.assert_allclose(upright['forearm'][0], [0, 0, 0.35], atol=1e-15)
    np.testing.assert_allclose(upright['hand'][0], [0.25, 0, 0.35], atol=1e-15)
    laid = link_poses(URDF, {'shoulder': math.pi / 2})
    np.testing.assert_allclose(laid['forearm'][0], [0.3, 0, 0.05], atol=1e-12)
    np.testing.assert_allclose(to_matrix(laid['forearm'][1]) @ [0, 0, 1], [1, 0, 0],
                               atol=1e-12)
    np.testing.assert_allclose(laid['hand'][0], [0.3, 0, 0.05 - 0.25], atol=1e-12)
    np.testing.assert_allclose(laid['tool0'][0], laid['hand'][0] + to_matrix(
        laid['hand'][1]) @ [0, 0, 0.12], atol=1e-12)


def test_joint_motion_entries_are_checked(package) -> None:
    scene(joint_motion=['shoulder:0.5:1.0', 'elbow:0.2:0.5:1.5'])
    for entries, message in ((['shoulder:0.5'], 'each entry is'),
                             (['shoulder:x:1'], 'each entry is'),
                             (['tool:0.1:1'], "'tool' is not a moving joint"),
                             (['nope:0.1:1'], "'nope' is not a moving joint")):
        with pytest.raises(ValueError, match=f'^joint_motion: {message}'):
            scene(joint_motion=entries)
    with pytest.raises(ValueError, match='^joint_motion: scripts joints of robot_description'):
        params.scene_from_values({'bodies': ['box'], 'joint_motion': ['shoulder:1:1']})


def test_scripted_joints_drive_the_links_in_collres_sim(package, tmp_path) -> None:
    """collres_sim --offline with joint_motion: every recorded link pose is the forward
    kinematics of the script at its stamp, its twist the motion since the last one; the
    swinging arm's forearm and hand move a crate on the floor."""
    import yaml

    from collres_ros.ros.bag import read_messages
    from collres_ros.ros.robot import link_poses
    from collres_ros.sim import main as sim_main
    path = tmp_path / 'arm.yaml'
    path.write_text(yaml.safe_dump({'/**': {'ros__parameters': {
        'bodies': ['floor', 'crate'], 'robot_description': URDF,
        'joint_motion': ['shoulder:0.9:0.5'], 'duration': 1.0, 'rate_hz': 240.0,
        'body': {'floor': {'shape': 'box', 'size': [2.0, 2.0, 0.2], 'static': True,
                           'position': [0.0, 0.0, -0.1]},
                 'crate': {'shape': 'box', 'size': [0.1, 0.1, 0.1], 'mass': 0.5,
                           'position': [0.45, 0.0, 0.05]}}}}}))
    assert sim_main(['--offline', '--params', str(path), '--record', str(tmp_path / 'bag')]) == 0
    messages = read_messages(tmp_path / 'bag')
    inputs = [m.msg for m in messages if m.topic == '/body_states']
    t0 = inputs[0].header.stamp.sec + inputs[0].header.stamp.nanosec * 1e-9
    previous = None
    for msg in inputs:
        t = msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9 - t0
        hand = [b for b in msg.bodies if b.name == 'hand'][0]
        p, q = link_poses(URDF, {'shoulder': 0.9 * math.sin(2 * math.pi * 0.5 * t)})['hand']
        got = np.array([hand.pose.position.x, hand.pose.position.y, hand.pose.position.z])
        np.testing.assert_allclose(got, p, atol=1e-9)
        if previous is not None:
            velocity = [hand.twist.linear.x, hand.twist.linear.y, hand.twist.linear.z]
            np.testing.assert_allclose(velocity, (p - previous[0]) / (t - previous[1]),
                                       atol=1e-6)
        previous = (p, t)
    touches = {(c.body_a, c.body_b, c.piece_b) for m in messages if m.topic == '/contacts'
               for c in m.msg.contacts if c.normal_impulse > 0.0 and c.body_a == 'crate'}
    assert touches & {('crate', 'forearm', 'wrist'), ('crate', 'hand', 'palm'),
                      ('crate', 'hand', 'finger'), ('crate', 'forearm', 'tube')}
    crate = [b for b in inputs[-1].bodies if b.name == 'crate'][0]
    # moved by the arm: the finger comes down 2 cm into the crate's top and squeezes it
    # against the floor (about 60 N s a step), and where the squeezed crate slips out is
    # decided by a tenth of a millimetre: from starts 0.05-0.3 mm apart it ends either
    # 4.6 cm or 11-14 cm away (either at every row_bound), never closer than 4.6 cm
    assert abs(crate.pose.position.x - 0.45) > 0.03
    # the bag's own params (links as bodies, no script) replay it to the same contacts
    from collres_ros.replay import main as replay_main
    assert replay_main([str(tmp_path / 'bag'), str(tmp_path / 'out'), '--quiet']) == 0
    replayed = [m.msg for m in read_messages(tmp_path / 'out') if m.topic == '/contacts']
    assert replayed == [m.msg for m in messages if m.topic == '/contacts']
