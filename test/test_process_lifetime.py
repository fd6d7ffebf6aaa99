"""SIGTERM and SIGKILL leave no process and no broken bag behind.

``collres_demo`` runs ``collres_node`` and ``collres_sim`` as children: ended by
SIGTERM it stops them as Ctrl-C does; killed by SIGKILL (no handler runs) the kernel
ends them (``PR_SET_PDEATHSIG``). ``collres_sim --offline --record`` ended by SIGTERM
finishes its bag as Ctrl-C does (metadata.yaml written, readable).
"""

from __future__ import annotations

import os
import signal
import subprocess
from pathlib import Path

import pytest

from collres_ros.ros import processes
from collres_ros.ros.bag import BagReader

ROOT = Path(__file__).resolve().parents[1]
BALL = ROOT / 'config' / 'scenes' / 'bouncing_ball.yaml'


def children(pid: int) -> list[int]:
    """Pids whose parent is ``pid`` (from /proc)."""
    found = []
    for entry in os.listdir('/proc'):
        if entry.isdigit():
            try:
                fields = Path(f'/proc/{entry}/stat').read_text().rsplit(')', 1)[1].split()
            except OSError:
                continue
            if int(fields[1]) == pid and fields[0] != 'Z':
                found.append(int(entry))
    return found


def alive(pid: int) -> bool:
    try:
        state = Path(f'/proc/{pid}/stat').read_text().rsplit(')', 1)[1].split()[0]
    except OSError:
        return False
    return state != 'Z'


@pytest.mark.slow
@pytest.mark.parametrize('sig', [signal.SIGTERM, signal.SIGKILL])
def test_the_demos_children_end_with_it(tmp_path: Path, ros_domain: int, sig: int) -> None:
    demo = processes.start('collres_demo', ['--params', str(BALL), '--duration', '60',
                                            '--out', str(tmp_path / 'out'), '--timeout', '600'],
                           env=processes.ros_env(ros_domain), log=tmp_path / 'demo.log')
    try:
        assert processes.wait_for(lambda: len(children(demo.pid)) >= 2
                                  or demo.poll() is not None, 60.0), demo.output()[-2000:]
        kids = children(demo.pid)
        print('demo', demo.pid, 'children', kids)
        assert len(kids) >= 2, demo.output()[-2000:]
        demo.send_signal(sig)
        code = demo.wait(60)
        gone = processes.wait_for(lambda: not any(alive(k) for k in kids), 30.0)
        print(sig, code, demo.output()[-800:])
        assert gone, f'children left running: {[k for k in kids if alive(k)]}'
        if sig == signal.SIGTERM:
            assert code == 130 and 'Traceback' not in demo.output()
    finally:
        for kid in children(demo.pid) + [demo.pid]:
            if alive(kid):
                os.kill(kid, signal.SIGKILL)


def test_sigterm_finishes_the_offline_bag(tmp_path: Path) -> None:
    bag = tmp_path / 'bag'
    sim = processes.start('collres_sim', ['--offline', '--params', str(BALL), '--duration',
                                          '86400', '--record', str(bag)],
                          log=tmp_path / 'sim.log')
    try:
        grown = processes.wait_for(lambda: any(p.stat().st_size > 2**20
                                               for p in bag.glob('*.mcap'))
                                   or sim.poll() is not None, 120.0)
        assert grown and sim.poll() is None, sim.output()[-1000:]
        sim.send_signal(signal.SIGTERM)
        code = sim.wait(60)
    except subprocess.TimeoutExpired:
        processes.stop(sim)
        raise
    print(code, sim.output()[-500:])
    assert code == 130 and 'Traceback' not in sim.output()
    assert (bag / 'metadata.yaml').is_file()
    with BagReader(bag) as reader:
        assert reader.topic_count('/body_states') > 100
