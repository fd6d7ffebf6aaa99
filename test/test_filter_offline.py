"""Collision filtering on the offline path: collres_sim --offline and collres_replay read
the same params (their reader is the node's), so a filtered pair gives no contacts there."""

from __future__ import annotations

from pathlib import Path

import pytest

pytest.importorskip('rclpy')

from collres_ros.replay import main as replay_main  # noqa: E402
from collres_ros.ros.bag import read_messages  # noqa: E402
from collres_ros.sim import main as sim_main  # noqa: E402

SCENE = '''/**:
  ros__parameters:
    world_frame: world
    bodies: [floor, ball, ghost]
{filter}
    body:
      floor: {{shape: plane, size: [0.0, 0.0, 1.0, 0.0], static: true}}
      ball: {{shape: sphere, size: [0.1], restitution: 0.5, position: [0.0, 0.0, 0.3]}}
      ghost: {{shape: sphere, size: [0.1], restitution: 0.5, position: [1.0, 0.0, 0.3]{bits}}}
collres_sim:
  ros__parameters:
    duration: 0.6
'''


def scene(tmp_path: Path, name: str, filter: str = '', bits: str = '') -> Path:
    path = tmp_path / f'{name}.yaml'
    path.write_text(SCENE.format(filter=filter, bits=bits))
    return path


def outcome(bag: Path) -> tuple[set[tuple[str, str]], float, float]:
    """Pairs in contact over the bag, and the lowest input heights of ball and ghost (m)."""
    pairs, low = set(), {'ball': 1e9, 'ghost': 1e9}
    for m in read_messages(bag):
        if m.topic == '/contacts':
            pairs |= {(c.body_a, c.body_b) for c in m.msg.contacts}
        elif m.topic == '/body_states':
            for b in m.msg.bodies:
                if b.name in low:
                    low[b.name] = min(low[b.name], b.pose.position.z)
    return pairs, low['ball'], low['ghost']


def test_sim_offline_and_replay_apply_ignore_pairs_and_bits(tmp_path: Path) -> None:
    ignored = scene(tmp_path, 'ignored', filter="    ignore_pairs: ['ghost:floor']")
    assert sim_main(['--offline', '--params', str(ignored), '--record',
                     str(tmp_path / 'rec')]) == 0
    pairs, ball, ghost = outcome(tmp_path / 'rec')
    print(f'recorded: contact pairs {sorted(pairs)}, lowest ball {ball:.3f} m, '
          f'ghost {ghost:.3f} m')
    assert pairs == {('floor', 'ball')}          # the ball lands on the floor ...
    assert ball > 0.1 - 0.005 and ghost < -1.0    # ... the ghost falls through it

    # replayed with the same file, with the params recorded in the bag, with bits instead
    masked = scene(tmp_path, 'masked', bits=', collision_mask: 65534')   # not bit 0: floor
    for args in (['--params', str(ignored)], [], ['--params', str(masked)]):
        out = tmp_path / f'out{len(list(tmp_path.glob("out*")))}'
        assert replay_main([str(tmp_path / 'rec'), str(out), *args]) == 0
        replayed, _, _ = outcome(out)
        print(args, '->', sorted(replayed))
        assert replayed == {('floor', 'ball')}

    # without the filter the same inputs make the ghost hit the floor
    plain = scene(tmp_path, 'plain')
    assert replay_main([str(tmp_path / 'rec'), str(tmp_path / 'plain_out'), '--params',
                        str(plain)]) == 0
    unfiltered, _, _ = outcome(tmp_path / 'plain_out')
    print('unfiltered ->', sorted(unfiltered))
    assert unfiltered == {('floor', 'ball'), ('floor', 'ghost')}


def test_bad_filter_params_stop_the_offline_tools_with_one_line(
        tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    bad = scene(tmp_path, 'bad', filter="    ignore_pairs: ['ghost:flor']")
    assert sim_main(['--offline', '--params', str(bad), '--record', str(tmp_path / 'b')]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert err == ["error: ignore_pairs: body 'flor' is not in bodies (got 'ghost:flor')"], err
    bits = scene(tmp_path, 'bits', bits=', collision_group: 65536')
    assert sim_main(['--offline', '--params', str(bits), '--record', str(tmp_path / 'c')]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert err == ['error: body.ghost.collision_group: allowed range [0, 65535] (got 65536)'], err
