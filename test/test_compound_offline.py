"""Compound bodies end to end, offline: collres_sim records contacts that name the touching
pieces, body_markers draw every piece, and collres_replay of the bag (its recorded params
carry the pieces) gives the same contacts."""

from __future__ import annotations

from collections import Counter
from pathlib import Path

import pytest

pytest.importorskip('rclpy')

from collres_ros.replay import main as replay_main  # noqa: E402
from collres_ros.ros.bag import read_messages  # noqa: E402
from collres_ros.sim import main as sim_main  # noqa: E402

# a table (top on two legs) whose centre of mass is its origin: pieces' frame shifted by
# -0.1625 m in z (test/core/test_compound_laws.py), feet 2 mm above the floor's top
SCENE = '''/**:
  ros__parameters:
    bodies: [floor, table]
    body:
      floor: {shape: box, size: [2.0, 2.0, 0.2], static: true, position: [0.0, 0.0, -0.1]}
      table:
        shapes: [top, left, right]
        mass: 2.0
        position: [0.0, 0.0, 0.1645]
        piece:
          top: {shape: box, size: [0.4, 0.1, 0.05], position: [0.0, 0.0, 0.0625]}
          left: {shape: box, size: [0.05, 0.1, 0.2], position: [-0.175, 0.0, -0.0625]}
          right: {shape: box, size: [0.05, 0.1, 0.2], position: [0.175, 0.0, -0.0625]}
collres_sim:
  ros__parameters:
    duration: 0.5
'''


def contacts(bag: Path) -> list[tuple[str, str, str, str]]:
    return [(c.body_a, c.piece_a, c.body_b, c.piece_b) for m in read_messages(bag)
            if m.topic == '/contacts' for c in m.msg.contacts]


def test_contacts_name_the_pieces_and_a_replay_reproduces_them(tmp_path: Path) -> None:
    params = tmp_path / 'table.yaml'
    params.write_text(SCENE)
    assert sim_main(['--offline', '--params', str(params), '--record',
                     str(tmp_path / 'rec')]) == 0
    recorded = contacts(tmp_path / 'rec')
    counts = Counter(recorded)
    print(counts)
    assert set(counts) == {('floor', '', 'table', 'left'), ('floor', '', 'table', 'right')}
    assert abs(counts[('floor', '', 'table', 'left')] - counts[('floor', '', 'table', 'right')]) \
        <= 4
    states = [m.msg for m in read_messages(tmp_path / 'rec') if m.topic == '/body_states']
    table = [b for b in states[-1].bodies if b.name == 'table'][0]
    assert abs(table.pose.position.z - 0.1625) < 1e-3      # resting on its feet
    markers = [m.msg for m in read_messages(tmp_path / 'rec') if m.topic == '/body_markers']
    meshes = [k for k in markers[-1].markers if k.ns == 'body_meshes' and k.points]
    assert sum(len(k.points) for k in meshes) == 3 * 12 * 3 + 12 * 3   # 3 pieces + floor
    assert replay_main([str(tmp_path / 'rec'), str(tmp_path / 'out'), '--quiet']) == 0
    assert contacts(tmp_path / 'out') == recorded
