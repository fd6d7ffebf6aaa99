"""Ctrl-C during a slow start ends the process at once, without a traceback.

rcl parses the params files inside ``rclpy.init``, in C: a file of 300,000 inline numbers
keeps it there for a minute or more, where Python's SIGINT handler cannot run. ``cli.ros_init``
gives SIGINT its OS default for that call (the process ends at once, as any C program on
Ctrl-C) and installs rclpy's handlers afterwards, as ``rclpy.init`` does.
"""

from __future__ import annotations

import signal
import subprocess
import time

import pytest

from collres_ros.ros import cli, processes


def test_sigint_has_its_os_default_while_rcl_parses(monkeypatch):
    import rclpy
    seen = {}

    def fake_init(**kwargs):
        seen['during'] = signal.getsignal(signal.SIGINT)
        seen['options'] = kwargs.get('signal_handler_options')
    monkeypatch.setattr(rclpy, 'init', fake_init)
    monkeypatch.setattr(rclpy, 'try_shutdown', lambda **kwargs: None)
    installed = []
    import rclpy.signals
    monkeypatch.setattr(rclpy.signals, 'install_signal_handlers', installed.append)
    before = signal.getsignal(signal.SIGINT)
    with cli.ros_init(args=['x']):
        after = signal.getsignal(signal.SIGINT)
    assert seen['during'] is signal.SIG_DFL
    assert after is before                          # Python's handler is back ...
    assert installed == [rclpy.signals.SignalHandlerOptions.ALL]   # ... then rclpy's


@pytest.mark.slow
def test_ctrl_c_during_a_slow_start_gives_no_traceback(tmp_path, ros_domain):
    numbers = ', '.join('0.5' for _ in range(150_000))
    scene = tmp_path / 'big.yaml'
    scene.write_text('/**:\n  ros__parameters:\n    bodies: [floor, rock]\n    body:\n'
                     '      floor: {shape: box, size: [10.0, 10.0, 0.2], static: true}\n'
                     f'      rock: {{shape: convex, points: [{numbers}]}}\n')
    for delay in (0.5, 5.0):
        node = processes.start('collres_node', ['--ros-args', '--params-file', str(scene)],
                               env=processes.ros_env(ros_domain), log=tmp_path / 'node.log')
        time.sleep(delay)    # a user's Ctrl-C at some point of the start (not a wait)
        node.send_signal(signal.SIGINT)
        try:
            code = node.wait(120)
        except subprocess.TimeoutExpired:
            processes.stop(node)
            raise
        out = node.output()
        print(delay, code, out[-500:])
        assert code in (0, 130, -signal.SIGINT) and "Traceback" not in out
        assert 'resolving' not in out        # it stopped, it did not start anyway
