"""Where the package's data files are: message definitions and config files.

Looked up in this order: inside the Python package (pip/venv installs), the
source tree next to it (editable installs, running from the repo), and the
ament index share directory (colcon and apt installs).
"""

from __future__ import annotations

import os
from pathlib import Path

PACKAGE = 'collres_ros'
_PACKAGE_DIR = Path(__file__).resolve().parent.parent   # collres_ros/


def _share_dir() -> Path | None:
    try:
        from ament_index_python.packages import get_package_share_directory
        return Path(get_package_share_directory(PACKAGE))
    except Exception:  # ament_index absent or package not in the index
        return None


def _candidates(*parts: str) -> list[Path]:
    roots = [_PACKAGE_DIR, _PACKAGE_DIR.parent]
    share = _share_dir()
    if share is not None:
        roots.append(share)
    return [root.joinpath(*parts) for root in roots]


def message_definition(name: str) -> str:
    """The text of ``msg/<name>.msg`` (e.g. 'BodyStateArray')."""
    for path in _candidates('msg', f'{name}.msg'):
        if path.is_file():
            return path.read_text()
    raise FileNotFoundError(f'message definition {name}.msg not found')


MESSAGE_NAMES = ('BodyState', 'BodyStateArray', 'Contact', 'ContactArray')


def config_path(relative: str = 'collres.yaml') -> Path:
    """Path of a shipped config file, e.g. 'collres.yaml' or 'scenes/pile.yaml'."""
    env = os.environ.get('COLLRES_CONFIG_DIR')
    roots = [Path(env)] if env else []
    for path in [r / relative for r in roots] + _candidates('config', relative):
        if path.is_file():
            return path
    raise FileNotFoundError(f'config file {relative} not found')
