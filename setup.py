"""pip build of collres_ros: the hand-written Python, the messages and the compiled core.

The messages and the compiled core (collres_ros/core/_native, sources in src/)
are built by the package's own CMakeLists.txt (the same one colcon uses)
through cmake/build_interfaces.py. Install into a venv that has
requirements.txt with ``pip install --no-build-isolation [-e] .``; on a ROS
install use colcon instead (see README.md).
"""

import os
import shutil
import sys

from setuptools import find_packages, setup
from setuptools.command.build_py import build_py

ROOT = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(ROOT, 'cmake'))


class BuildWithInterfaces(build_py):
    """build_py that also generates the messages and ships config/ in the package."""

    def run(self) -> None:
        import build_interfaces  # cmake/build_interfaces.py
        super().run()
        build_dir = os.path.join(ROOT, 'build', 'interfaces')
        if getattr(self, 'editable_mode', False):
            build_interfaces.build(os.path.join(ROOT, 'collres_ros'), build_dir)
            return
        package_dir = os.path.join(self.build_lib, 'collres_ros')
        build_interfaces.build(package_dir, build_dir)
        shutil.copytree(os.path.join(ROOT, 'config'), os.path.join(package_dir, 'config'),
                        dirs_exist_ok=True)


setup(
    name='collres_ros',
    version='0.1.0',
    description='Rigid-body contact resolution for ROS 2 topic pipelines (coal, impulses)',
    license='Apache-2.0',
    python_requires='>=3.11',
    packages=find_packages(include=['collres_ros', 'collres_ros.*']),
    package_data={'collres_ros': ['*.so', '_lib/*.so', 'msg/*.msg', 'srv/*.srv',
                                  'core/_native*.so', '_interfaces/tf2_msgs/*.py',
                                  '_interfaces/tf2_msgs/*.so', '_interfaces/tf2_msgs/msg/*']},
    install_requires=['numpy', 'coal', 'PyYAML', 'rosbags', 'matplotlib'],
    cmdclass={'build_py': BuildWithInterfaces},
    # the executables: the same scripts colcon installs (CMakeLists.txt), each of which makes a
    # Ctrl-C before its main runs end the process quietly (collres_ros/entry.py)
    scripts=['scripts/collres_node', 'scripts/collres_sim', 'scripts/collres_replay',
             'scripts/collres_demo', 'scripts/collres_decompose'],
)
