"""The README documents every parameter exactly as the code declares it."""

from __future__ import annotations

import re
from pathlib import Path

from collres_ros.ros.params import markdown_table

ROOT = Path(__file__).resolve().parents[1]
BEGIN, END = '<!-- parameters:begin -->', '<!-- parameters:end -->'


def readme_table() -> str:
    text = (ROOT / 'README.md').read_text()
    return text[text.index(BEGIN) + len(BEGIN):text.index(END)].strip()


def update_readme() -> None:
    """Rewrite the README's parameter section from the code (run this file as a script)."""
    path = ROOT / 'README.md'
    text = path.read_text()
    head, rest = text.split(BEGIN, 1)
    _, tail = rest.split(END, 1)
    path.write_text(f'{head}{BEGIN}\n{markdown_table().strip()}\n{END}{tail}')


def test_readme_parameter_tables_equal_the_declared_parameters() -> None:
    assert readme_table() == markdown_table().strip(), (
        'README parameters are out of date: run `.venv/bin/python test/test_readme.py`')


def test_readme_names_both_setup_commands_and_the_executables() -> None:
    text = (ROOT / 'README.md').read_text()
    assert re.search(r'^make demo\b', text, re.M) and re.search(r'^make test\b', text, re.M)
    for exe in ('collres_node', 'collres_sim', 'collres_replay', 'collres_demo'):
        assert f'`{exe}' in text


if __name__ == '__main__':
    update_readme()
