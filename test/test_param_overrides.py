"""``--ros-args -p NAME:=VALUE`` works as ``--help`` says, with the shipped params files.

rcl puts a ``-p`` value in the ``/**`` section and applies a node-specific section
(``/**/collres_node``) after it, so a setting kept there silently beat the command
line. The shipped files keep every setting in ``/**``; collres_sim reads ``-p``
values over its file too. Each test runs the documented form.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from collres_ros.ros import processes
from collres_ros.ros.bag import BagReader
from ros_harness import Peer, answered

ROOT = Path(__file__).resolve().parents[1]
BALL = ROOT / 'config' / 'scenes' / 'bouncing_ball.yaml'


def node_parameters(domain: int, names: list[str]) -> list:
    """The values collres_node reports for ``names`` (its get_parameters service)."""
    from rcl_interfaces.srv import GetParameters
    from rclpy.parameter import parameter_value_to_python
    peer = Peer(domain)
    try:
        client = peer.node.create_client(GetParameters, '/collres_node/get_parameters')
        assert client.wait_for_service(timeout_sec=30.0), 'collres_node has no parameters'
        result = answered(peer, lambda: client.call_async(GetParameters.Request(names=names)))
        return [parameter_value_to_python(v) for v in result.values]
    finally:
        peer.close()


@pytest.mark.slow
@pytest.mark.parametrize('files', [[], ['--params-file', str(BALL)],
                                   ['--params-file', str(ROOT / 'config' / 'collres.yaml')]])
def test_a_command_line_parameter_wins_over_the_shipped_files(tmp_path: Path,
                                                              ros_domain: int,
                                                              files: list[str]) -> None:
    node = processes.start('collres_node', ['--ros-args', *files, '-p', 'contact_wrench:=true',
                                            '-p', 'solver.velocity_iterations:=3'],
                           env=processes.ros_env(ros_domain), log=tmp_path / 'node.log')
    try:
        values = node_parameters(ros_domain, ['contact_wrench', 'solver.velocity_iterations'])
        print(files, values)
        assert values == [True, 3], node.output()[-1000:]
    finally:
        processes.stop(node)


def test_the_sim_takes_command_line_parameters_over_its_file(tmp_path: Path) -> None:
    from collres_ros.sim import main
    bag = tmp_path / 'bag'
    assert main(['--offline', '--params', str(BALL), '--record', str(bag), '--ros-args',
                 '-p', 'rate_hz:=100.0', '-p', 'duration:=0.5']) == 0
    with BagReader(bag) as reader:
        assert reader.topic_count('/body_states') == 51     # 0.5 s at 100 Hz, both ends
