"""Ctrl-C during a slow start ends the process at once, without a traceback.

rcl parses the params files inside ``rclpy.init``, in C: a file of 300,000 inline numbers
keeps it there for a minute or more, where Python's SIGINT handler cannot run. ``cli.ros_init``
gives SIGINT its OS default for that call (the process ends at once, as any C program on
Ctrl-C) and installs rclpy's handlers afterwards, as ``rclpy.init`` does.
"""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys
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


# a Ctrl-C at the first import of a module, in an executable run as the shell runs it: the
# finder sends the process SIGINT when that module is first looked for
CTRL_C_AT_IMPORT = """
import os, runpy, signal, sys
exe, module = sys.argv[1:3]
class CtrlC:
    def find_spec(self, name, path=None, target=None):
        if name == module:
            sys.meta_path.remove(self)
            os.kill(os.getpid(), signal.SIGINT)
sys.meta_path.insert(0, CtrlC())
sys.argv = [exe, '--help']
runpy.run_path(exe, run_name='__main__')
"""


@pytest.mark.parametrize('name', ['collres_node', 'collres_sim', 'collres_replay'])
@pytest.mark.parametrize('module', ['glob', 'datetime'])
def test_ctrl_c_while_an_executable_imports_ends_it_quietly(name, module):
    """A Ctrl-C while the executable imports ends it at once, quietly: at ``glob``, inside
    ``import collres_ros`` (the package's libraries are loaded); at ``datetime``, inside
    numpy's compiled module, which turns the KeyboardInterrupt into an ImportError with a
    traceback ("Importing the numpy C-extensions failed") unless SIGINT is the OS default
    there."""
    exe = shutil.which(name, path=os.path.dirname(sys.executable))
    result = subprocess.run([sys.executable, '-c', CTRL_C_AT_IMPORT, exe, module],
                            capture_output=True, text=True, timeout=60)
    out = result.stdout + result.stderr
    print(result.returncode, out[-2000:])
    assert result.returncode in (-signal.SIGINT, 130) and 'Traceback' not in out
    assert 'usage' not in out   # it stopped there: the help was never printed


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


def test_a_signal_while_the_node_is_created_exits_0(monkeypatch, ros_domain):
    """SIGINT or SIGTERM after rclpy's handlers are installed shuts the context down; the node
    being created then fails in rcl ("the given context is not valid"): that is the signal's
    quiet exit 0, not a traceback."""
    import rclpy
    from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy
    from rclpy.signals import SignalHandlerOptions

    from collres_ros.ros import node as node_module

    class Interrupted:
        def __init__(self, *args, **kwargs):
            rclpy.shutdown()   # what rclpy's signal handler does, in the middle of the start
            raise _rclpy.RCLError('error creating node: the given context is not valid')
    monkeypatch.setattr(node_module, 'CollresNode', Interrupted)
    rclpy.init(args=['collres_node'], signal_handler_options=SignalHandlerOptions.NO)
    try:
        assert node_module._spin(['collres_node']) == 0
    finally:
        rclpy.try_shutdown()
