"""The compiled core is built, importable and linked against coal's C++ library."""

from __future__ import annotations

from pathlib import Path

from collres_ros.core import _native


def test_native_module_loads_coal_and_combines():
    maps = Path('/proc/self/maps').read_text()
    assert 'libcoal.so' in maps, 'the compiled core is not linked against libcoal'
    assert _native.combine(0.25, 1.0, _native.CombineRule.geometric) == 0.5
