"""A robot's URDF (``robot_description``) as bodies: one kinematic body per link.

Every link with ``<collision>`` elements becomes a body named after the link:
a compound of one piece per element (sphere, box, cylinder along z, or a mesh's
convex hull with its ``scale``), each at the element's ``<origin>`` in the link
frame (xyz in m; rpy fixed-axis roll about x, pitch about y, yaw about z, as
URDF defines it). Links are kinematic (infinite mass, never pushed): their poses
come from outside, in ``body_states`` under the link's name, in the world frame.
Links without collision elements are not bodies. Mesh paths: ``package://pkg/...``
(the package's share directory, by ament_index), ``file:///abs/path``, or a path
relative to the params file. Errors are one line naming the link.

The description is turned into the flat parameters a params file would hold
(``body.<link>.kinematic``, ``body.<link>.shapes``, ``body.<link>.piece.<p>.*``),
so the one validator reads robots and hand-written bodies alike, and a link's
materials or collision bits can still be set as ``body.<link>.*``.

Parser: ``urdf_parser_py`` (PyPI ``urdf-parser-py``), the ROS parser of
``ros/urdf_parser_py`` that a ROS install ships as ``urdfdom_py``: the same module
name in a venv and on a ROS install, and it reads URDF as robot_state_publisher
publishes it.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Optional

import numpy as np

from collres_ros.core.config import SIZE_RANGE

NAME_PATTERN = re.compile(r'^[A-Za-z][A-Za-z0-9_]*$')


@dataclass(frozen=True)
class Robot:
    """What a description adds to a scene: link bodies, their parameters and the pairs of
    links that never collide (all pairs, or with self-collision only adjacent ones)."""

    name: str
    links: tuple[str, ...]                   # link bodies, in the description's order
    values: dict[str, Any]                   # flat parameters of those bodies
    ignored: tuple[tuple[str, str], ...]     # link pairs that never collide


def quaternion_of_rpy(roll: float, pitch: float, yaw: float) -> tuple[float, ...]:
    """Unit quaternion (x, y, z, w) of URDF's rpy: R = Rz(yaw) Ry(pitch) Rx(roll)."""
    cr, sr = math.cos(roll / 2), math.sin(roll / 2)
    cp, sp = math.cos(pitch / 2), math.sin(pitch / 2)
    cy, sy = math.cos(yaw / 2), math.sin(yaw / 2)
    return (sr * cp * cy - cr * sp * sy, cr * sp * cy + sr * cp * sy,
            cr * cp * sy - sr * sp * cy, cr * cp * cy + sr * sp * sy)


def mesh_path(filename: str, base_dir: Optional[Path]) -> Path:
    """The file a URDF mesh filename names (ValueError with the reason when none)."""
    if filename.startswith('package://'):
        package, _, rest = filename[len('package://'):].partition('/')
        try:
            from ament_index_python.packages import (PackageNotFoundError,
                                                     get_package_share_directory)
        except ImportError:
            raise ValueError(f'{filename}: ament_index_python is not installed') from None
        try:
            return Path(get_package_share_directory(package)) / rest
        except PackageNotFoundError:
            raise ValueError(f'{filename}: package {package!r} not found (AMENT_PREFIX_PATH)') \
                from None
    if filename.startswith('file://'):
        return Path(filename[len('file://'):])
    if '://' in filename:
        raise ValueError(f'{filename}: only package:// and file:// are resolved')
    path = Path(filename)
    return path if path.is_absolute() else (base_dir or Path.cwd()) / path


def parse(text: str) -> Any:
    """The urdf_parser_py model of a URDF text (ValueError: one line)."""
    from urdf_parser_py.urdf import URDF
    try:
        return URDF.from_xml_string(text.encode())
    except Exception as error:   # lxml and the parser raise many kinds: all are a bad text
        reason = str(error).strip().splitlines()[0] if str(error).strip() else \
            type(error).__name__
        raise ValueError(f'robot_description: not a URDF ({reason[:200]})') from None


def robot_from_urdf(text: str, base_dir: Optional[Path],
                    read_mesh: Callable[[Path], np.ndarray],
                    self_collision: bool = False) -> Robot:
    """The link bodies of a URDF text (``read_mesh``: vertices (K, 3) of a mesh file, the
    params' safe reader). ValueError (one line) naming the link for anything unusable."""
    model = parse(text)
    values: dict[str, Any] = {}
    links = []
    for link in model.links:
        if not link.collisions:
            continue
        where = f'robot_description: link {link.name!r}'
        if not NAME_PATTERN.match(link.name or ''):
            raise ValueError(f'{where}: a link with collisions must be named as a body '
                             f'({NAME_PATTERN.pattern}: its name is part of topic names)')
        names: list[str] = []
        for k, collision in enumerate(link.collisions):
            name = collision.name if collision.name and NAME_PATTERN.match(collision.name) \
                and collision.name not in names else f'collision_{k}'
            names.append(name)
            at = f'body.{link.name}.piece.{name}'
            values.update(_geometry(f'{where}: collision {k}', at, collision.geometry,
                                    base_dir, read_mesh))
            origin = collision.origin
            xyz = [float(v) for v in (origin.xyz if origin and origin.xyz else (0, 0, 0))]
            rpy = [float(v) for v in (origin.rpy if origin and origin.rpy else (0, 0, 0))]
            values[f'{at}.position'] = xyz
            values[f'{at}.orientation'] = list(quaternion_of_rpy(*rpy))
        values[f'body.{link.name}.shapes'] = names
        values[f'body.{link.name}.kinematic'] = True
        links.append(link.name)
    adjacent = {tuple(sorted((j.parent, j.child))) for j in model.joints}
    ignored = tuple((a, b) for i, a in enumerate(links) for b in links[i + 1:]
                    if not self_collision or tuple(sorted((a, b))) in adjacent)
    return Robot(model.name or '', tuple(links), values, ignored)


def _geometry(where: str, at: str, geometry: Any, base_dir: Optional[Path],
              read_mesh: Callable[[Path], np.ndarray]) -> dict[str, Any]:
    kind = type(geometry).__name__
    if kind == 'Sphere':
        return {f'{at}.shape': 'sphere', f'{at}.size': [float(geometry.radius)]}
    if kind == 'Box':
        return {f'{at}.shape': 'box', f'{at}.size': [float(v) for v in geometry.size]}
    if kind == 'Cylinder':
        return {f'{at}.shape': 'cylinder',
                f'{at}.size': [float(geometry.radius), float(geometry.length)]}
    if kind == 'Mesh':
        try:
            path = mesh_path(str(geometry.filename), base_dir)
            points = read_mesh(path)
        except (OSError, ValueError) as error:
            reason = error.strerror if isinstance(error, OSError) and error.strerror \
                else str(error)
            raise ValueError(f'{where}: cannot read mesh {geometry.filename!r} ({reason})') \
                from None
        scale = np.array(geometry.scale if geometry.scale else (1.0, 1.0, 1.0), float)
        points = points * scale
        if not np.isfinite(points).all() or np.abs(points).max(initial=0.0) > SIZE_RANGE[1]:
            raise ValueError(f'{where}: mesh {geometry.filename!r} has vertices that are not '
                             f'finite or beyond {SIZE_RANGE[1]:g} m')
        return {f'{at}.shape': 'convex', f'{at}.points': points.reshape(-1).tolist()}
    raise ValueError(f'{where}: no collision shape for <{kind.lower()}>')


Pose = tuple[np.ndarray, np.ndarray]   # position (3,) m, quaternion (4,) x, y, z, w
IDENTITY_POSE: Pose = (np.zeros(3), np.array([0.0, 0.0, 0.0, 1.0]))


class Kinematics:
    """Forward kinematics of a URDF (parsed once): a child link sits at its joint's origin
    in its parent's frame, turned about the joint axis by the joint's position (rad;
    revolute, continuous) or moved along it (m; prismatic); other joints are fixed. Root
    links sit at ``base``."""

    def __init__(self, text: str, base: Pose = IDENTITY_POSE) -> None:
        model = parse(text)
        self.base = base
        self.links = [link.name for link in model.links]
        self.joints = {j.name: j for j in model.joints}
        self._by_child = {j.child: j for j in model.joints}

    def poses(self, positions: Optional[dict[str, float]] = None) -> dict[str, Pose]:
        """World pose of every link with the joints at ``positions`` (missing: 0)."""
        from collres_ros.core.rotation import multiply, to_matrix
        positions = positions or {}
        poses: dict[str, Pose] = {}

        def pose(link: str, depth: int = 0) -> Pose:
            if link in poses:
                return poses[link]
            joint = self._by_child.get(link)
            if joint is None or depth > len(self.links):
                found = (np.array(self.base[0], float), np.array(self.base[1], float))
            else:
                p, q = pose(joint.parent, depth + 1)
                origin = joint.origin
                xyz = np.array(origin.xyz if origin and origin.xyz else (0, 0, 0), float)
                rpy = origin.rpy if origin and origin.rpy else (0, 0, 0)
                p = p + to_matrix(q) @ xyz
                q = multiply(q, np.array(quaternion_of_rpy(*rpy)))
                axis = np.array(joint.axis if joint.axis else (1, 0, 0), float)
                axis /= max(np.linalg.norm(axis), 1e-300)
                value = float(positions.get(joint.name, 0.0))
                if joint.type in ('revolute', 'continuous'):
                    q = multiply(q, np.append(axis * np.sin(value / 2), np.cos(value / 2)))
                elif joint.type == 'prismatic':
                    p = p + to_matrix(q) @ (axis * value)
                found = (p, q / np.linalg.norm(q))
            poses[link] = found
            return found

        for link in self.links:
            pose(link)
        return poses


def link_poses(text: str, positions: Optional[dict[str, float]] = None,
               base: Pose = IDENTITY_POSE) -> dict[str, Pose]:
    """World pose of every link of a URDF text with its joints at ``positions``
    (``Kinematics``)."""
    return Kinematics(text, base).poses(positions)


def joint_motion(entries: list[str], text: str) -> tuple[tuple[str, float, float, float], ...]:
    """The scripted joints of ``joint_motion`` entries "joint:amplitude:frequency[:phase]"
    (ValueError, one line naming joint_motion, for a bad entry or an unknown joint)."""
    if not entries:
        return ()
    if not text:
        raise ValueError(f'joint_motion: scripts joints of robot_description, which is empty '
                         f'(got {entries[0]!r})')
    joints = Kinematics(text).joints
    motion = []
    for entry in entries:
        name, *numbers = entry.split(':')
        try:
            values = [float(v) for v in numbers]
        except ValueError:
            values = []
        if len(values) not in (2, 3) or not all(math.isfinite(v) for v in values):
            raise ValueError(f'joint_motion: each entry is "joint:amplitude:frequency[:phase]", '
                             f'finite numbers (got {entry!r})')
        moving = ('revolute', 'continuous', 'prismatic')
        if name not in joints or joints[name].type not in moving:
            raise ValueError(f'joint_motion: {name!r} is not a moving joint of '
                             f'robot_description (got {entry!r})')
        amplitude, frequency, *phase = values
        motion.append((name, amplitude, frequency, phase[0] if phase else 0.0))
    return tuple(motion)
