"""A tiny harness for running the package's executables as child processes.

Used by the end-to-end tests and by ``collres_demo``: start an executable
(``collres_node``, ``collres_sim``, ...) with its own environment (a private
``ROS_DOMAIN_ID``, discovery limited to localhost), wait on predicates with
deadlines (never a bare sleep), stop it with SIGINT, then SIGTERM, then
SIGKILL, and read what it printed. Each child runs in its own session, so a
Ctrl-C in the terminal reaches the parent only, which stops its children; and
each child gets SIGTERM from the kernel when its parent dies (Linux
``PR_SET_PDEATHSIG``), so a parent killed by SIGKILL leaves no child behind.
"""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Callable, Mapping, Optional, Sequence

# Console script -> module with main(), used when the script is not installed.
MODULES = {'collres_node': 'collres_ros.node', 'collres_sim': 'collres_ros.sim',
           'collres_replay': 'collres_ros.replay', 'collres_demo': 'collres_ros.demo',
           'collres_decompose': 'collres_ros.decompose'}


class Process(subprocess.Popen):
    """A started child: a Popen with its name and the path of its combined output."""

    name: str
    log_path: Path

    def output(self) -> str:
        """Everything the child wrote so far (stdout and stderr interleaved)."""
        try:
            return self.log_path.read_text(errors='replace')
        except OSError:
            return ''


def command(script: str) -> list[str]:
    """argv prefix running ``script``: the installed executable next to this
    interpreter, else one on PATH, else ``python -m <module>``."""
    local = Path(sys.executable).parent / script
    if local.is_file() and os.access(local, os.X_OK):
        return [str(local)]
    if script in MODULES:
        return [sys.executable, '-m', MODULES[script]]
    found = shutil.which(script)
    if found:
        return [found]
    raise FileNotFoundError(f'executable {script} not found')


def ros_env(domain_id: Optional[int] = None, base: Optional[Mapping[str, str]] = None,
            **extra: str) -> dict[str, str]:
    """Environment for a ROS child: localhost discovery, unbuffered Python output."""
    env = dict(os.environ if base is None else base)
    env['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
    env['PYTHONUNBUFFERED'] = '1'
    env.setdefault('RCUTILS_COLORIZED_OUTPUT', '0')
    if domain_id is not None:
        env['ROS_DOMAIN_ID'] = str(domain_id)
    env.update(extra)
    return env


def _die_with_parent() -> Optional[Callable[[], None]]:
    """A ``preexec_fn`` asking the kernel to SIGTERM the child when this process dies
    (Linux prctl PR_SET_PDEATHSIG; None elsewhere). Loaded before the fork, so the child
    only makes the call; a parent already gone by then ends the child at once."""
    if not sys.platform.startswith('linux'):
        return None
    import ctypes
    prctl = ctypes.CDLL(None, use_errno=True).prctl
    parent = os.getpid()
    set_death_signal = 1   # PR_SET_PDEATHSIG, <linux/prctl.h>

    def arm() -> None:
        prctl(set_death_signal, int(signal.SIGTERM), 0, 0, 0)
        if os.getppid() != parent:
            os._exit(1)
    return arm


def start(script: str, args: Sequence[str] = (), env: Optional[Mapping[str, str]] = None,
          log: Optional[str | Path] = None, cwd: Optional[str | Path] = None) -> Process:
    """Start ``script args`` with ``env`` (default: ``ros_env()``); output to ``log``.

    Without ``log`` the output goes to a temporary file (``process.log_path``).
    """
    if log is None:
        handle, name = tempfile.mkstemp(prefix=f'{script}-', suffix='.log')
        os.close(handle)
        log = name
    log_path = Path(log)
    log_path.parent.mkdir(parents=True, exist_ok=True)
    with open(log_path, 'wb') as sink:
        proc = Process(command(script) + list(args), stdin=subprocess.DEVNULL, stdout=sink,
                       stderr=subprocess.STDOUT, env=dict(env) if env is not None else ros_env(),
                       cwd=cwd, start_new_session=True, preexec_fn=_die_with_parent())
    proc.name = script
    proc.log_path = log_path
    return proc


def wait_for(predicate: Callable[[], bool], timeout: float, period: float = 0.01) -> bool:
    """Poll ``predicate`` until it is true (True) or ``timeout`` s pass (False)."""
    deadline = time.monotonic() + timeout
    while True:
        if predicate():
            return True
        if time.monotonic() >= deadline:
            return False
        time.sleep(period)


def stop(proc: subprocess.Popen, timeouts: Sequence[float] = (10.0, 5.0, 5.0)) -> int:
    """Stop a child: SIGINT, then SIGTERM, then SIGKILL, each after a timeout (s).

    Returns the exit code (negative: killed by that signal). A child that has
    already exited just returns its code.
    """
    for sig, timeout in zip((signal.SIGINT, signal.SIGTERM, signal.SIGKILL), timeouts):
        if proc.poll() is not None:
            break
        try:
            proc.send_signal(sig)
        except ProcessLookupError:
            break
        try:
            proc.wait(timeout)
        except subprocess.TimeoutExpired:
            continue
    return proc.wait()
