"""``make goldens`` changes nothing when nothing changed.

tools/regenerate_goldens.py regenerates each scene's input and golden bags and
writes them only when their messages differ from the ones in place: on a clean
clone it leaves every file of test/data as it is (bytes and times), and it writes
a scene that is missing.
"""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SCENES = ('fast_sphere_wall', 'billiard_break')


def snapshot(folder: Path) -> dict[str, tuple[bytes, int]]:
    return {str(f.relative_to(folder)): (f.read_bytes(), f.stat().st_mtime_ns)
            for f in sorted(folder.rglob('*')) if f.is_file()}


def test_regenerating_unchanged_goldens_changes_no_file(tmp_path: Path) -> None:
    for scene in SCENES:
        shutil.copytree(ROOT / 'test' / 'data' / scene, tmp_path / scene)
    before = snapshot(tmp_path)
    result = subprocess.run([sys.executable, str(ROOT / 'tools' / 'regenerate_goldens.py'),
                             '--out', str(tmp_path), *SCENES], capture_output=True, text=True,
                            timeout=600)
    print(result.stdout, result.stderr[-2000:])
    assert result.returncode == 0
    assert snapshot(tmp_path) == before
    assert result.stdout.count('(unchanged: the same messages)') == len(SCENES)
    shutil.rmtree(tmp_path / SCENES[0])
    result = subprocess.run([sys.executable, str(ROOT / 'tools' / 'regenerate_goldens.py'),
                             '--out', str(tmp_path), SCENES[0]], capture_output=True,
                            text=True, timeout=600)
    assert result.returncode == 0 and (tmp_path / SCENES[0] / 'golden').is_dir()
