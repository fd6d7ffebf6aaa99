#!/usr/bin/env python3
"""Build the collres_ros messages and compiled core with CMake into a Python package dir.

Used by the Makefile (in-tree, for the editable install) and by setup.py
(into build_lib, for ``pip install .``). It runs the package's own
CMakeLists.txt (rosidl_generate_interfaces) against the ROS 2 wheels of the
running interpreter's environment, into a scratch prefix, then copies:

* ``collres_ros/msg/`` and ``collres_ros/srv/`` (generated Python, plus the definitions),
* ``collres_ros/collres_ros_s__rosidl_typesupport_*.so`` (extension modules),
* ``collres_ros/_lib/libcollres_ros__rosidl_*.so`` (preloaded by collres_ros/__init__.py,
  because rmw dlopen()s typesupport libraries by bare name),
* ``collres_ros/core/_native*.so`` (the compiled contact core, sources in src/),
* where the environment has no ``tf2_msgs`` (the PyPI ROS wheels lack it):
  ``cmake/tf2_msgs`` (its TFMessage, generated the same way) as
  ``collres_ros/_interfaces/tf2_msgs/`` (appended to the import path by
  collres_ros/__init__.py) with its libraries in ``collres_ros/_lib/``.

Usage: build_interfaces.py DEST_PACKAGE_DIR [--build-dir DIR]
"""

import argparse
import glob
import hashlib
import importlib.util
import os
import shutil
import subprocess
import sys
import sysconfig

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
INPUTS = ['CMakeLists.txt', 'package.xml', 'cmake/build_interfaces.py'] + sorted(
    os.path.relpath(p, ROOT) for pattern in ('cmake/*.cmake', 'msg/*.msg', 'src/*.h', 'src/*.cpp',
                                             'cmake/tf2_msgs/*.*', 'cmake/tf2_msgs/msg/*.msg')
    for p in glob.glob(os.path.join(ROOT, pattern)))
TF2_MSGS = os.path.join(ROOT, 'cmake', 'tf2_msgs')   # TFMessage, where tf2_msgs is missing
JOBS = os.environ.get('CMAKE_BUILD_PARALLEL_LEVEL', '2')   # the compiled core needs ~0.6 GB a job


def _fingerprint() -> str:
    digest = hashlib.sha256(sys.executable.encode())
    for rel in INPUTS:
        with open(os.path.join(ROOT, rel), 'rb') as f:
            digest.update(rel.encode() + b'\0' + f.read())
    return digest.hexdigest()


def build(dest: str, build_dir: str) -> None:
    """Generate and compile the interfaces; copy them into ``dest`` (a collres_ros/ dir)."""
    stamp = os.path.join(dest, 'msg', '.build-stamp')
    fingerprint = _fingerprint()
    native = glob.glob(os.path.join(dest, 'core', '_native*.so'))
    # tf2_msgs is not on PyPI (a directory named tf2_msgs without __init__.py, as
    # cmake/tf2_msgs beside this script, is a namespace package: no tf2_msgs installed)
    installed = importlib.util.find_spec('tf2_msgs')
    generate_tf = installed is None or installed.origin is None
    generated_tf = os.path.isdir(os.path.join(dest, '_interfaces', 'tf2_msgs'))
    if native and os.path.exists(stamp) and open(stamp).read() == fingerprint \
            and generated_tf == generate_tf:
        print('interfaces up to date')
        return
    prefix = sys.prefix
    env = dict(os.environ)
    for var in ('AMENT_PREFIX_PATH', 'CMAKE_PREFIX_PATH'):
        env[var] = os.pathsep.join(p for p in (prefix, env.get(var, '')) if p)
    install = os.path.join(build_dir, 'install')
    pyver = f'python{sys.version_info.major}.{sys.version_info.minor}'
    site = os.path.join('lib', pyver, 'site-packages')
    generator = ['-G', 'Ninja'] if shutil.which('ninja') else []
    shutil.rmtree(install, ignore_errors=True)
    projects = [(ROOT, os.path.join(build_dir, 'cmake'), ['-DCOLLRES_SKIP_PYTHON_INSTALL=ON'])]
    if generate_tf:
        projects.append((TF2_MSGS, os.path.join(build_dir, 'tf2_msgs'), []))
    run = []
    for source, binary, extra in projects:
        run += [
            ['cmake', '-S', source, '-B', binary, *generator,
             f'-DPython3_EXECUTABLE={sys.executable}',
             f'-DPython3_INCLUDE_DIR={sysconfig.get_paths()["include"]}',
             f'-DCMAKE_INSTALL_PREFIX={install}', f'-DPYTHON_INSTALL_DIR={site}',
             '-DBUILD_TESTING=OFF', '-DCMAKE_BUILD_TYPE=Release', *extra],
            ['cmake', '--build', binary, '--parallel', JOBS],
            ['cmake', '--install', binary],
        ]
    for cmd in run:
        result = subprocess.run(cmd, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                                text=True)
        if result.returncode:
            sys.stderr.write(result.stdout[-6000:])
            raise SystemExit(f'error: {" ".join(cmd[:2])} failed (exit {result.returncode})')
    generated = os.path.join(install, site, 'collres_ros')
    for kind in ('msg', 'srv'):
        shutil.rmtree(os.path.join(dest, kind), ignore_errors=True)
        shutil.copytree(os.path.join(generated, kind), os.path.join(dest, kind),
                        ignore=shutil.ignore_patterns('*.c', '__pycache__'))
    for ext in glob.glob(os.path.join(generated, 'collres_ros_s__*.so')):
        shutil.copy2(ext, dest)
    lib_dir = os.path.join(dest, '_lib')
    shutil.rmtree(lib_dir, ignore_errors=True)
    os.makedirs(lib_dir)
    for lib in glob.glob(os.path.join(install, 'lib', 'libcollres_ros__*.so')):
        shutil.copy2(lib, lib_dir)
    interfaces = os.path.join(dest, '_interfaces')
    shutil.rmtree(interfaces, ignore_errors=True)
    if generate_tf:
        shutil.copytree(os.path.join(install, site, 'tf2_msgs'),
                        os.path.join(interfaces, 'tf2_msgs'),
                        ignore=shutil.ignore_patterns('*.c', '__pycache__'))
        for lib in glob.glob(os.path.join(install, 'lib', 'libtf2_msgs__*.so')):
            shutil.copy2(lib, lib_dir)
    for old in glob.glob(os.path.join(dest, 'core', '_native*.so')):
        os.remove(old)
    for ext in glob.glob(os.path.join(generated, 'core', '_native*.so')):
        shutil.copy2(ext, os.path.join(dest, 'core'))
    for kind in ('msg', 'srv'):
        for definition in glob.glob(os.path.join(ROOT, kind, f'*.{kind}')):
            shutil.copy2(definition, os.path.join(dest, kind))
    with open(stamp, 'w') as f:
        f.write(fingerprint)
    print(f'interfaces built into {dest}')


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('dest', help='the collres_ros package directory to place them in')
    parser.add_argument('--build-dir', default=os.path.join(ROOT, 'build', 'interfaces'))
    args = parser.parse_args()
    build(os.path.abspath(args.dest), os.path.abspath(args.build_dir))


if __name__ == '__main__':
    main()
