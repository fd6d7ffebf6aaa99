"""What a newcomer meets: no progress noise in logs, no warnings to ignore, no dangling references.

* Progress lines are redrawn with carriage returns, so they are drawn only on a
  terminal (stdout and stderr): in a log file or a pipe there are none.
* The test run filters the one warning nobody here can act on (lark-parser's
  deprecated ``sre_*`` imports, pulled in by the ROS wheels' rosidl_parser).
* The code and docs refer only to what ships in the repository.
"""

from __future__ import annotations

import os
import pty
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SCENE = ROOT / 'config' / 'scenes' / 'box_stack.yaml'


def _sim(bag: Path) -> list[str]:
    return [sys.executable, '-m', 'collres_ros.sim', '--offline', '--params', str(SCENE),
            '--duration', '0.3', '--record', str(bag)]


def _replay(bag: Path, out: Path) -> list[str]:
    return [sys.executable, '-m', 'collres_ros.replay', str(bag), str(out)]


def test_no_progress_lines_in_a_log(tmp_path: Path) -> None:
    pytest.importorskip('rclpy')
    for command in (_sim(tmp_path / 'rec'), _replay(tmp_path / 'rec', tmp_path / 'out')):
        result = subprocess.run(command, capture_output=True, text=True, timeout=300, cwd=ROOT)
        print(result.stdout, result.stderr)
        assert result.returncode == 0, result.stderr
        assert '\r' not in result.stdout + result.stderr
        assert result.stderr.strip() == '', 'stderr of a clean run is empty in a log'
    assert 'recorded 73 steps' in subprocess.run(
        _sim(tmp_path / 'again'), capture_output=True, text=True, timeout=300,
        cwd=ROOT).stdout


def test_progress_is_drawn_on_a_terminal(tmp_path: Path) -> None:
    pytest.importorskip('rclpy')
    for command in (_sim(tmp_path / 'rec'), _replay(tmp_path / 'rec', tmp_path / 'out')):
        leader, follower = pty.openpty()
        proc = subprocess.Popen(command, stdout=follower, stderr=follower, cwd=ROOT)
        os.close(follower)
        chunks = []
        while True:
            try:
                data = os.read(leader, 4096)
            except OSError:   # the child closed the terminal
                break
            if not data:
                break
            chunks.append(data)
        os.close(leader)
        assert proc.wait(timeout=300) == 0
        text = b''.join(chunks).decode(errors='replace')
        print(repr(text[-200:]))
        assert re.search(r'\r(collres_sim|replay): \d+/\d+ steps', text), text


def test_pytest_filters_the_lark_deprecation_with_its_reason() -> None:
    text = (ROOT / 'pyproject.toml').read_text()
    assert "ignore:module 'sre_constants' is deprecated:DeprecationWarning:lark" in text
    assert "ignore:module 'sre_parse' is deprecated:DeprecationWarning:lark" in text
    assert 'rosidl_parser' in text, 'say why the warning is filtered'


# documents that live outside the repository (the patterns are split so this file passes)
OUTSIDE = [re.compile(p, re.I) for p in (
    r'DESIGN' r'\.md', r'STYLE' r'\.md', r'\bseed' r'/', r'/work' r'/', r'\blec' r'ture\b',
    r'\bissue' r' \d+', r'ros-wheels' r'\.md')]


def test_no_references_to_documents_outside_the_repository() -> None:
    files = subprocess.run(['git', 'ls-files'], cwd=ROOT, capture_output=True, text=True,
                           check=True).stdout.split()
    found = []
    for name in files:
        path = ROOT / name
        if name.startswith('test/data/') or not path.is_file() or path.suffix in (
                '.mcap', '.db3', '.png', '.stl'):
            continue
        try:
            text = path.read_text()
        except UnicodeDecodeError:
            continue
        for number, line in enumerate(text.splitlines(), 1):
            if any(p.search(line) for p in OUTSIDE):
                found.append(f'{name}:{number}: {line.strip()}')
    assert not found, '\n'.join(found)
