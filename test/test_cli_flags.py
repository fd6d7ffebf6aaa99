"""collres_sim and collres_demo flags: every one range-checked before anything is created,
one ``error: --flag: ...`` line and exit 2; the demo honours an exported ROS_DOMAIN_ID
"""

from __future__ import annotations

import subprocess
from pathlib import Path

import pytest

from collres_ros.ros import processes

ROOT = Path(__file__).resolve().parents[1]
BALL = str(ROOT / 'config' / 'scenes' / 'bouncing_ball.yaml')


def run(script, args, tmp_path, timeout=120):
    result = subprocess.run(processes.command(script) + args, capture_output=True, text=True,
                            timeout=timeout, cwd=tmp_path, env=processes.ros_env())
    print(result.returncode, repr(result.stdout), repr(result.stderr))
    return result


@pytest.mark.parametrize('args, flag', [
    (['--duration', 'nan'], '--duration'), (['--duration', 'inf'], '--duration'),
    (['--duration', '-1'], '--duration'), (['--rate', 'nan'], '--rate'),
    (['--rate', '0'], '--rate'), (['--wait', 'nan'], '--wait'),
    (['--step-timeout', '0'], '--step-timeout'), (['--subscribers', '-1'], '--subscribers'),
    (['--subscribers', '1.5'], '--subscribers'),
])
def test_sim_flags_are_range_checked_first(tmp_path, args, flag):
    bag = tmp_path / 'bag'
    result = run('collres_sim', ['--offline', '--params', BALL, '--record', str(bag), *args],
                 tmp_path)
    assert result.returncode == 2 and result.stdout == ''
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f'error: {flag}: must be ')
    assert not bag.exists()


@pytest.mark.parametrize('args, flag', [
    (['--timeout', '0'], '--timeout'), (['--timeout', 'nan'], '--timeout'),
    (['--duration', '-1'], '--duration'), (['--duration', 'nan'], '--duration'),
    (['--domain-id', '999'], '--domain-id'), (['--domain-id', '-1'], '--domain-id'),
])
def test_demo_flags_are_range_checked_first(tmp_path, args, flag):
    out = tmp_path / 'out'
    result = run('collres_demo', ['--out', str(out), *args], tmp_path)
    assert result.returncode == 2
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f'error: {flag}: must be ')
    assert not out.exists()


@pytest.mark.slow
def test_a_demo_that_times_out_ends_with_one_error_line_not_an_abort(tmp_path, ros_domain):
    result = run('collres_demo', ['--out', str(tmp_path / 'out'), '--duration', '0.2',
                                  '--timeout', '0.01'], tmp_path)
    assert result.returncode == 1
    assert 'terminate called' not in result.stderr and 'Traceback' not in result.stderr
    assert result.stderr.strip().splitlines()[-1].startswith('error: collres_sim did not finish')


def test_the_demo_honours_an_exported_domain_id(monkeypatch):
    from collres_ros import demo
    monkeypatch.setenv('ROS_DOMAIN_ID', '57')
    assert demo._private_domain_id() == 57
    monkeypatch.delenv('ROS_DOMAIN_ID')
    assert 1 <= demo._private_domain_id() <= 100
