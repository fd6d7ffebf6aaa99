"""flake8 with the ament settings (setup.cfg: 99 columns) over every Python file we ship."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def test_flake8_is_clean() -> None:
    targets = ['collres_ros', 'test', 'bench', 'tools', 'cmake', 'setup.py']
    result = subprocess.run([sys.executable, '-m', 'flake8', *targets], cwd=ROOT,
                            capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stdout + result.stderr
