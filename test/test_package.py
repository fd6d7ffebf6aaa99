"""Package metadata, executables and the colcon build of a normal ROS install."""

from __future__ import annotations

import ast
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from catkin_pkg.package import parse_package

ROOT = Path(__file__).resolve().parents[1]
EXECUTABLES = ('collres_node', 'collres_sim', 'collres_replay', 'collres_demo',
               'collres_decompose')

# Python import -> the package.xml key that provides it.
IMPORT_TO_KEY = {
    'rclpy': 'rclpy', 'std_msgs': 'std_msgs', 'geometry_msgs': 'geometry_msgs',
    'visualization_msgs': 'visualization_msgs', 'diagnostic_msgs': 'diagnostic_msgs',
    'builtin_interfaces': 'builtin_interfaces', 'rcl_interfaces': 'rclpy',
    'numpy': 'python3-numpy', 'yaml': 'python3-yaml', 'matplotlib': 'python3-matplotlib',
    'coal': 'coal', 'ament_index_python': 'rclpy', 'rosbags': 'python3-rosbags-pip',
    'coacd': 'python3-coacd-pip', 'urdf_parser_py': 'urdfdom_py',
}


def _imported_top_level_modules() -> set[str]:
    names: set[str] = set()
    for path in (ROOT / 'collres_ros').rglob('*.py'):
        if '/msg/' in str(path) or '/srv/' in str(path):
            continue
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Import):
                names.update(alias.name.split('.')[0] for alias in node.names)
            elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                names.add(node.module.split('.')[0])
    return names


def test_package_xml_is_format_3_and_lists_what_the_code_imports() -> None:
    package = parse_package(str(ROOT / 'package.xml'))
    package.validate()
    assert package.package_format == 3
    assert package.name == 'collres_ros'
    declared = {d.name for d in package.build_depends + package.exec_depends
                + package.buildtool_depends + package.build_export_depends}
    for key in ('rosidl_default_generators', 'rosidl_default_runtime', 'rclpy', 'std_msgs',
                'geometry_msgs', 'visualization_msgs', 'diagnostic_msgs',
                'builtin_interfaces', 'python3-numpy', 'coal'):
        assert key in declared, f'package.xml misses {key}'
    assert 'rosidl_interface_packages' in [g.name for g in package.member_of_groups]
    imported = _imported_top_level_modules()
    missing = sorted(IMPORT_TO_KEY[m] for m in imported
                     if m in IMPORT_TO_KEY and IMPORT_TO_KEY[m] not in declared)
    assert not missing, f'imported but not declared in package.xml: {missing}'
    assert 'rosbags' in imported


def test_license_file_matches_package_xml() -> None:
    package = parse_package(str(ROOT / 'package.xml'))
    assert [str(name) for name in package.licenses] == ['Apache-2.0']
    text = (ROOT / 'LICENSE').read_text()
    assert 'Apache License' in text.splitlines()[1] and 'Version 2.0' in text.splitlines()[2]


def test_colcon_test_runs_the_suite_by_default() -> None:
    text = (ROOT / 'CMakeLists.txt').read_text()
    block = text[text.index('if(BUILD_TESTING'):]
    assert block.startswith('if(BUILD_TESTING)\n'), 'tests need no extra flag'
    assert 'ament_add_pytest_test(' in block[:block.index('endif()')]


def test_physics_core_imports_without_ros() -> None:
    code = ('import sys; sys.modules["rclpy"] = None; sys.modules["rosbags"] = None\n'
            'import collres_ros.core, collres_ros.core.types, collres_ros.core.config\n'
            'import pkgutil, importlib\n'
            'for m in pkgutil.iter_modules(collres_ros.core.__path__):\n'
            '    importlib.import_module("collres_ros.core." + m.name)\n'
            'print("ok")\n')
    result = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True,
                            cwd=ROOT, timeout=60)
    assert result.returncode == 0, result.stderr
    assert result.stdout.strip() == 'ok'


@pytest.mark.parametrize('name', EXECUTABLES)
def test_every_executable_answers_help(name: str) -> None:
    exe = shutil.which(name, path=os.path.dirname(sys.executable))
    assert exe, f'{name} is not installed'
    result = subprocess.run([exe, '--help'], capture_output=True, text=True, timeout=60)
    assert result.returncode == 0, result.stderr
    assert 'usage' in result.stdout.lower()
    assert len(result.stdout.split()) > 20, 'help text too thin to be useful'
    script = ROOT / 'scripts' / name  # what pip and colcon install (`ros2 run` runs)
    assert os.access(script, os.X_OK)
    # through the entry point, SIGINT at its OS default until the imports are done
    assert f'from collres_ros.entry import {name.split("_")[1]} as main' in script.read_text()


@pytest.mark.slow
def test_colcon_builds_the_package_against_the_ros_environment(tmp_path: Path) -> None:
    """`colcon build` as on a ROS install, with this venv's ROS wheels as the underlay."""
    source = tmp_path / 'src' / 'collres_ros'
    shutil.copytree(ROOT, source, ignore=shutil.ignore_patterns(
        '.venv', '.git', 'build', 'install', 'log', 'demo_out', '_lib', '*.so', '__pycache__',
        'msg', 'srv', 'test', 'bench', '.pytest_cache', '.hypothesis'))
    shutil.copytree(ROOT / 'msg', source / 'msg')
    shutil.copytree(ROOT / 'srv', source / 'srv')
    prefix = sys.prefix
    env = dict(os.environ, AMENT_PREFIX_PATH=prefix, CMAKE_PREFIX_PATH=prefix,
               PATH=f'{os.path.dirname(sys.executable)}:{os.environ["PATH"]}')
    # colcon's make arguments are -jN -lN (N cores): past a load of N, make runs one job at
    # a time, and on a loaded 2-core machine the serial build took more than 600 s (the
    # compiled core alone about 6 min at load 6). A -j of our own in MAKEFLAGS replaces
    # both; the deadline only catches a hung build.
    env['MAKEFLAGS'] = f'-j{len(os.sched_getaffinity(0))}'
    colcon = os.path.join(os.path.dirname(sys.executable), 'colcon')
    result = subprocess.run(
        [colcon, 'build', '--base-paths', 'src', '--cmake-args',
         f'-DPython3_EXECUTABLE={sys.executable}', '-DBUILD_TESTING=OFF'],
        cwd=tmp_path, env=env, capture_output=True, text=True, timeout=1500)
    assert result.returncode == 0, result.stdout[-3000:] + result.stderr[-3000:]
    install = tmp_path / 'install' / 'collres_ros'
    site = next(install.glob('lib/python3*/site-packages'))
    assert (site / 'collres_ros' / 'msg' / '_contact_array.py').is_file()
    assert (site / 'collres_ros' / 'core' / 'types.py').is_file()
    assert len(list((site / 'collres_ros' / 'core').glob('_native*.so'))) == 1
    for name in EXECUTABLES:
        assert os.access(install / 'lib' / 'collres_ros' / name, os.X_OK)
    assert (install / 'share' / 'collres_ros' / 'config' / 'collres.yaml').is_file()
    for viewer in ('launch/collres.launch.py', 'rviz/collres.rviz',
                   'foxglove/collres_layout.json'):
        assert (install / 'share' / 'collres_ros' / viewer).is_file(), viewer
    # the colcon-installed messages import and serialise from the install tree
    check = ('from collres_ros.msg import ContactArray, Contact\n'
             'from rclpy.serialization import serialize_message, deserialize_message\n'
             'm = ContactArray(contacts=[Contact(body_a="a", state=Contact.IMPACT)])\n'
             'assert deserialize_message(serialize_message(m), ContactArray) == m\n'
             'from collres_ros.srv import GetContacts\n'
             'r = GetContacts.Response(stepped=True, contacts=[Contact(body_b="b")])\n'
             'assert deserialize_message(serialize_message(r), GetContacts.Response) == r\n'
             'import collres_ros.msg; print(collres_ros.msg.__file__)\n'
             'from collres_ros.core import _native; print(_native.__file__)\n'
             'assert _native.combine(0.25, 1.0, _native.CombineRule.geometric) == 0.5\n')
    run_env = dict(env, PYTHONPATH=str(site),
                   LD_LIBRARY_PATH=f'{install / "lib"}:{os.environ.get("LD_LIBRARY_PATH", "")}')
    result = subprocess.run([sys.executable, '-c', check], cwd=tmp_path, env=run_env,
                            capture_output=True, text=True, timeout=60)
    assert result.returncode == 0, result.stderr
    assert result.stdout.count(str(site)) == 2


def test_executables_are_thin_mains_that_never_import_one_another() -> None:
    """node, sim, replay, demo import the core and collres_ros.ros, never each other."""
    mains = {'node', 'sim', 'replay', 'demo'}
    for name in sorted(mains):
        tree = ast.parse((ROOT / 'collres_ros' / f'{name}.py').read_text())
        imported = set()
        for node in ast.walk(tree):
            if isinstance(node, ast.Import):
                imported.update(alias.name for alias in node.names)
            elif isinstance(node, ast.ImportFrom) and node.module:
                imported.add(node.module)
                if node.module == 'collres_ros':
                    imported.update(f'collres_ros.{alias.name}' for alias in node.names)
        others = {f'collres_ros.{m}' for m in mains - {name}}
        assert not imported & others, f'{name}.py imports {sorted(imported & others)}'
