"""Scenes from ROS 2 parameters: a params YAML file or a node's flat parameter values.

Both roads meet in ``scene_from_values``, the one validator: every error is a
``ValueError`` whose message is one line naming the parameter and what is
allowed, e.g. ``body.ball.restitution: allowed range [0.0, 1.0] (got 1.5)``.

File schema (README, "Parameters"): ``world_frame``, ``bodies``,
``body.<name>.*``, ``solver.*``, the node settings and the sim settings, in the
``/**`` section (the shipped files: there a command-line ``-p`` wins over them)
or in ``collres_node`` / ``collres_sim`` sections. The
defaults, units and ranges come from ``collres_ros.core.config``. The node's
parameter declarations (``descriptor``, ``declare_scene``, ``plain_value``)
import rclpy's types when called; importing this module imports no ROS.
"""

from __future__ import annotations

import array
import functools
import math
import os
import re
import stat
import struct
from collections import Counter
from dataclasses import dataclass, field, fields, replace
from pathlib import Path
from typing import Any, Callable, Iterable, Mapping, Optional

import numpy as np

from collres_ros.core import decomposition
from collres_ros.core.config import (
    BODY_PARAMS, MESH_MAX_BYTES, MESH_SUFFIXES, NODE_PARAMS, PIECE_PARAMS, POSITION_LIMIT,
    SCENE_PARAMS, SIM_PARAMS, SIZE_RANGE, SOLVER_PARAMS, NodeSettings, ParamSpec, SimSettings,
    SolverSettings, check_value, range_text)
from collres_ros.core.shapes import (centre_of_mass, hull_problem, hull_vertices, mesh_points,
                                     mesh_surface, triangle_corners)
from collres_ros.core.types import (COMPOUND, TRIANGLE_MESH, BodySpec, BodyStates,
                                    CollisionFilter, Piece)
from collres_ros.ros import params_yaml, robot

NODE_NAME = 'collres_node'
SIM_NAME = 'collres_sim'
NAME_PATTERN = re.compile(r'^[A-Za-z][A-Za-z0-9_]*$')
# rmw's limit on a full topic name (RMW_TOPIC_MAX_NAME_LENGTH = 255 - 8), and the longest
# topic a body name goes into, in the root namespace: /bodies/<name>/twist/corrected
TOPIC_MAX_LENGTH = 247
LONGEST_BODY_TOPIC = '/bodies/{}/twist/corrected'
NAME_MAX_LENGTH = TOPIC_MAX_LENGTH - len(LONGEST_BODY_TOPIC.format(''))
# Parameters every rclpy node has; accepted and ignored here.
ROS_BUILTIN = ('use_sim_time', 'start_type_description_service')

_SHAPES = next(spec for spec in BODY_PARAMS if spec.name == 'shapes')

# Runtime-changeable parameters: solver settings, materials, collision filter, node settings.
MATERIALS = ('restitution', 'static_friction', 'kinetic_friction', 'rolling_resistance',
             'torsional_friction')
COLLISION_BITS = ('collision_group', 'collision_mask')
PAIR_SEPARATOR = ':'   # ignore_pairs entries are "a:b"
SIZES = {'sphere': ('[r]', 1), 'box': ('[x, y, z]', 3), 'capsule': ('[r, length]', 2),
         'cylinder': ('[r, length]', 2), 'cone': ('[r, length]', 2),
         'plane': ('[nx, ny, nz, d]', 4)}


@dataclass(frozen=True)
class Scene:
    """A validated scene: bodies, their initial (static: fixed) states and all settings.

    ``initial``: world frame, one row per body in ``bodies`` order (treat as
    read-only; copy before changing). ``values``: every parameter (dotted
    name as the node declares it) with its validated value, defaults filled in.
    ``base_dir``: where relative mesh paths are resolved.
    """

    world_frame: str
    bodies: tuple[BodySpec, ...]
    initial: BodyStates
    solver: SolverSettings = SolverSettings()
    node: NodeSettings = NodeSettings()
    sim: SimSettings = SimSettings()
    values: Mapping[str, Any] = field(default_factory=dict)
    base_dir: Optional[Path] = None
    # link pairs of robot_description that never collide (robot.Robot.ignored)
    robot_ignored: tuple[tuple[str, str], ...] = ()

    @property
    def names(self) -> list[str]:
        return [b.name for b in self.bodies]

    @property
    def pieces(self) -> dict[str, list[str]]:
        """Piece names of each compound body written as pieces (``body.<name>.shapes``)."""
        return pieces_of(self.values, self.names)

    @property
    def kinematic(self) -> np.ndarray:
        """(N,) bool: bodies moved by collres_sim at their prescribed twist (also static)."""
        return np.array([bool(self.values.get(f'body.{b.name}.kinematic', False))
                         for b in self.bodies], bool)

    def index(self, name: str) -> int:
        """Index of a body by name (ValueError when unknown)."""
        return self.names.index(name)

    @property
    def collision_filter(self) -> CollisionFilter:
        """Which pairs may collide: the bodies' collision bits, ``ignore_pairs`` and the
        robot's link pairs."""
        return collision_filter_of(self.values, self.names, self.robot_ignored)


# --- the table of every parameter -------------------------------------------------------------

def _renamed(spec: ParamSpec, name: str) -> ParamSpec:
    """``spec`` under another name (``dataclasses.replace`` re-runs ``__init__``: 13 us a
    call, 0.6 s of a 1000-body start, where 47,000 specs are renamed)."""
    renamed = object.__new__(ParamSpec)
    renamed.__dict__.update(spec.__dict__, name=name)
    return renamed


def body_param(name: str, spec: ParamSpec) -> ParamSpec:
    """``spec`` renamed to ``body.<name>.<param>``."""
    return _renamed(spec, f'body.{name}.{spec.name}')


def piece_param(name: str, piece: str, spec: ParamSpec) -> ParamSpec:
    """``spec`` renamed to ``body.<name>.piece.<piece>.<param>``."""
    return _renamed(spec, f'body.{name}.piece.{piece}.{spec.name}')


def pieces_of(values: Mapping[str, Any], body_names: Iterable[str]) -> dict[str, list[str]]:
    """{body: its piece names} of the bodies whose ``shapes`` (validated values) is set."""
    return {name: list(values.get(f'body.{name}.shapes') or []) for name in body_names
            if values.get(f'body.{name}.shapes')}


def node_specs(body_names: Iterable[str] = (),
               pieces: Optional[Mapping[str, Iterable[str]]] = None) -> list[ParamSpec]:
    """Every parameter collres_node declares, full dotted names, in table order
    (``pieces``: {body: piece names} of the compound bodies)."""
    specs = list(SCENE_PARAMS)
    for name in body_names:
        specs += [body_param(name, s) for s in BODY_PARAMS]
        for piece in (pieces or {}).get(name, ()):
            specs += [piece_param(name, piece, s) for s in PIECE_PARAMS]
    specs += [replace(s, name=f'solver.{s.name}') for s in SOLVER_PARAMS]
    return specs + list(NODE_PARAMS)


_NODE_PARAM_NAMES = frozenset(s.name for s in NODE_PARAMS)


def all_specs(body_names: Iterable[str] = (),
              pieces: Optional[Mapping[str, Iterable[str]]] = None) -> list[ParamSpec]:
    """Every parameter of a scene file (node's plus sim's)."""
    return node_specs(body_names, pieces) + list(SIM_PARAMS)


def is_runtime_changeable(name: str) -> bool:
    """Whether a running node accepts a change of this parameter (others are read-only)."""
    if name.startswith('solver.') or name in _NODE_PARAM_NAMES:
        return name != 'queue_depth'
    if name == 'ignore_pairs':
        return True
    parts = name.split('.')
    return len(parts) == 3 and parts[0] == 'body' and parts[2] in MATERIALS + COLLISION_BITS


# --- reading files ----------------------------------------------------------------------------

def _flatten(prefix: str, value: Any, out: dict[str, Any]) -> None:
    if isinstance(value, dict) and value:
        for key, item in value.items():
            _flatten(f'{prefix}.{key}' if prefix else str(key), item, out)
    else:
        # rcl reads `{}` and `[]` as "not set": so do we
        out[prefix] = None if value in ({}, []) else value


def fully_qualified_name(namespace: str, name: str) -> str:
    """``/ns/name`` of a node (``namespace`` '/', '', 'r1' or '/r1/sub')."""
    namespace = '/' + namespace.strip('/') if namespace.strip('/') else ''
    return f'{namespace}/{name}'


def section_matches(section: str, fqn: str) -> bool:
    """Whether a params-file section applies to the node ``fqn``, by rcl's rules.

    A section without a leading ``/`` is absolute (``collres_node`` is
    ``/collres_node``: the root namespace only); ``*`` stands for one name
    token, ``/**`` for any number of leading namespaces (none included).
    """
    key = section if section.startswith('/') else '/' + section
    pattern = ''
    for token in key.split('/')[1:]:
        pattern += {'**': '(/[^/]+)*', '*': '/[^/]+'}.get(token, '/' + re.escape(token))
    return re.fullmatch(pattern, fqn) is not None


def read_params_file(path: str | Path, node_names: Iterable[str] = (NODE_NAME, SIM_NAME),
                     namespace: str = '/') -> dict[str, Any]:
    """Flat {dotted name: value} of the sections that apply to ``node_names`` in ``namespace``.

    The sections are chosen as rcl chooses them for a node of that fully
    qualified name (``/**``, ``/**/collres_node``, ``/r1/collres_node``,
    ``/*/collres_node``, ``/r1/**``; a bare ``collres_node`` is the root
    namespace's), merged leaf by leaf in file order (later sections win), and
    read with rclpy's own reader (``rclpy.parameter.parameter_dict_from_yaml_file``).
    Where that reader departs from rcl, rcl's reading is kept: a quoted value
    stays a string, ``[]`` is not set, a list mixing types is refused.
    ValueError (one line) for unreadable YAML or a malformed section.
    """
    path = Path(path)
    document = params_yaml.parse(params_yaml.read_text(path), str(path))
    return params_from_document(document, str(path), node_names, namespace)


def params_from_document(document: Any, source: str,
                         node_names: Iterable[str] = (NODE_NAME, SIM_NAME),
                         namespace: str = '/') -> dict[str, Any]:
    """``read_params_file`` of a document ``params_yaml.parse`` read (``source`` names it)."""
    if not isinstance(document, dict):
        raise ValueError(f'{source}: not a ROS 2 params file (top level must be a mapping)')
    fqns = [fully_qualified_name(namespace, name) for name in node_names]
    values: dict[str, Any] = {}
    for section, body in document.items():
        if not any(section_matches(str(section), fqn) for fqn in fqns):
            continue
        if not isinstance(body, dict) or 'ros__parameters' not in body:
            raise ValueError(f'{source}: section {section!r} has no ros__parameters')
        params = body['ros__parameters'] or {}
        if not isinstance(params, dict):
            raise ValueError(f'{source}: {section}.ros__parameters must be a mapping')
        flat: dict[str, Any] = {}
        _flatten('', params, flat)
        for name, leaf in flat.items():
            if isinstance(leaf, list):
                shown = _short(name if name.isprintable() else repr(name), 100)
                if any(isinstance(v, (list, dict)) for v in leaf):
                    raise ValueError(f'{shown}: a list must hold plain values, as rcl '
                                     'requires (no nested lists or mappings)')
                if len({type(v) for v in leaf}) > 1:
                    got = _show(leaf)
                    raise ValueError(f'{shown}: a list must hold values of one type, as rcl '
                                     'requires (write 1.0, not 1, among doubles) '
                                     f'(got {got if len(got) < 100 else got[:96] + " ..."})')
            values[name] = leaf   # later sections win, leaf by leaf
    return values


def load_scene(path: str | Path, namespace: str = '/',
               overrides: Optional[Mapping[str, Any]] = None) -> Scene:
    """Load a scene from a params file (ValueError with one line naming the parameter).

    The file is read as collres_node and collres_sim in ``namespace`` read it
    (see ``read_params_file``); ``overrides`` (``-p NAME:=VALUE`` of the command
    line) win over it. A missing file raises FileNotFoundError (an OSError).
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f'params file not found: {path}')
    values = {**read_params_file(path, namespace=namespace), **(overrides or {})}
    return scene_from_values(values, path.resolve().parent)


def load_recorded_scene(text: Any, source: str, namespace: str = '/') -> Scene:
    """The scene of params text recorded in a bag: untrusted, so read within the params
    file bounds and self-contained (a ``mesh`` path is refused: the recorder inlines the
    vertices). ValueError (one line) for anything else, a text that is not a string too."""
    if not isinstance(text, str):
        raise ValueError(f'{source}: recorded params must be the text of a params file '
                         f'(got a {type(text).__name__})')
    document = params_yaml.parse(text, source)
    return scene_from_values(params_from_document(document, source, namespace=namespace),
                             None, files=False)


# --- the validator ----------------------------------------------------------------------------

def _fail(name: str, why: str, value: Any) -> None:
    raise ValueError(f'{name}: {why} (got {_show(value)})')


def _short(text: str, limit: int = 40) -> str:
    """A name cut to ``limit`` characters for an error line."""
    return text if len(text) <= limit else text[:limit - 3] + '...'


def _show(value: Any, limit: int = 12) -> str:
    """A value as written in an error line (long lists and strings are cut)."""
    if isinstance(value, str):
        return repr(_short(value, 80))
    if isinstance(value, (list, tuple)):
        more = f', ... ({len(value)} values)' if len(value) > limit else ''
        return '[' + ', '.join(_show(v) for v in value[:limit]) + more + ']'
    if isinstance(value, bool):
        return 'true' if value else 'false'
    return str(value)


def _typed(spec: ParamSpec, value: Any) -> Any:
    """``value`` coerced to the spec's type (an integer where a double goes is fine)."""
    if value is None:
        value = spec.default
    kind = spec.type
    if kind == 'double' and isinstance(value, int) and not isinstance(value, bool):
        value = float(value)
    if kind == 'integer' and isinstance(value, float):
        # a running node refuses a double for an integer parameter: so does the file
        _fail(spec.name, 'must be an integer' + (f', write {int(value)}' if value.is_integer()
                                                 and math.isfinite(value) else ''), value)
    if kind in ('double_array', 'string_array'):
        if isinstance(value, tuple):
            value = list(value)
        if not isinstance(value, list):
            _fail(spec.name, f'must be a list ({spec.type})', value)
        if kind == 'double_array':
            if not all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in value):
                _fail(spec.name, 'must be a list of numbers', value)
            value = [float(v) for v in value]
            if not all(math.isfinite(v) for v in value):
                _fail(spec.name, 'values must be finite', value)
            lo, hi = spec.minimum, spec.maximum
            if spec.name.split('.')[-1] != 'size' and lo is not None and hi is not None \
                    and not all(lo <= v <= hi for v in value):
                _fail(spec.name, f'values must be in [{lo:g}, {hi:g}]' + (
                    f' {spec.unit}' if spec.unit else ''), value)
        elif not all(isinstance(v, str) for v in value):
            _fail(spec.name, 'must be a list of strings', value)
        return value
    if kind == 'double' and isinstance(value, float) and not math.isfinite(value):
        _fail(spec.name, 'must be finite', value)
    check_value(spec, value)
    return value


def _typed_values(named: Iterable[tuple[str, ParamSpec]], raw: Mapping[str, Any]
                  ) -> dict[str, Any]:
    """{full name: ``_typed`` value} of ``named`` ((full name, its kind's spec), in order)
    from ``raw`` (None: not set). A kind's default is typed and checked once (a list copied
    per name), a set value is checked under its kind's spec and, when refused, again under
    its full name for the error line: the 24,000 parameters of a 1000-body scene, most of
    them defaults, each checked under a spec renamed for it took 0.2 s of the start."""
    typed: dict[str, Any] = {}
    defaults: dict[int, Any] = {}   # id(spec) -> its typed default
    for name, spec in named:
        value = raw.get(name)
        if value is None:
            default = defaults.get(id(spec), defaults)
            if default is defaults:
                default = defaults[id(spec)] = _typed(spec, None)
            typed[name] = list(default) if isinstance(default, list) else default
            continue
        try:
            typed[name] = _typed(spec, value)
        except ValueError:
            if spec.name == name:
                raise
            _typed(_renamed(spec, name), value)   # the same refusal under its own name
            raise
    return typed


def _vector(name: str, value: list[float], count: int, what: str) -> tuple[float, ...]:
    if len(value) != count:
        _fail(name, f'needs {count} values {what}', value)
    return tuple(value)


def _mesh_bytes(path: Path) -> bytes:
    """The bytes of a mesh file: a regular .obj/.stl file below ``MESH_MAX_BYTES`` only.

    Opened without blocking and checked on the open file, so a FIFO, a device
    (``/dev/zero``) or a file swapped in after a check is never read. OSError
    or ValueError with the reason.
    """
    if path.suffix.lower() not in MESH_SUFFIXES:
        raise ValueError(f'unsupported mesh format {path.suffix or "(none)"!r} '
                         f'(use {" or ".join(MESH_SUFFIXES)})')
    handle = os.open(path, os.O_RDONLY | getattr(os, 'O_NONBLOCK', 0))
    with os.fdopen(handle, 'rb') as file:
        info = os.fstat(file.fileno())
        if not stat.S_ISREG(info.st_mode):
            raise ValueError('not a regular file')
        if info.st_size > MESH_MAX_BYTES:
            raise ValueError(f'{info.st_size} bytes, more than the limit of {MESH_MAX_BYTES}')
        data = file.read(MESH_MAX_BYTES + 1)
    if len(data) > MESH_MAX_BYTES:
        raise ValueError(f'more than the limit of {MESH_MAX_BYTES} bytes')
    return data


def _read_mesh(path: Path) -> np.ndarray:
    """Vertices (K, 3) of an OBJ or STL file, read safely, parsed by the core's mesh reader."""
    return mesh_points(_mesh_bytes(path), path.suffix)


def _mesh_file(key: str, mesh: str, base_dir: Optional[Path], files: bool, carried: str,
               read: Callable[[Path], np.ndarray]) -> tuple[Path, np.ndarray]:
    """(path, ``read(path)``) of the mesh file ``key.mesh`` names (relative to ``base_dir``);
    one line naming ``key.mesh`` when it cannot be read, or in a recorded scene (``files``
    false), which carries its ``carried`` (points) and names no file."""
    if not files:
        _fail(f'{key}.mesh', f'a recorded scene carries its {carried} (points), it names no '
              'file: a mesh path from a bag is not read', mesh)
    path = Path(mesh) if Path(mesh).is_absolute() else (base_dir or Path.cwd()) / mesh
    try:
        return path, read(path)
    except (OSError, ValueError, struct.error) as error:
        reason = error.strerror if isinstance(error, OSError) and error.strerror \
            else str(error)
        _fail(f'{key}.mesh', f'cannot read mesh {path} ({reason})', mesh)


def _convex_points(name: str, values: Mapping[str, Any], base_dir: Optional[Path],
                   files: bool = True) -> tuple[tuple[float, float, float], ...]:
    mesh, flat = values[f'{name}.mesh'], values[f'{name}.points']
    if mesh:
        path, points = _mesh_file(name, mesh, base_dir, files, 'vertices', _read_mesh)
        if not np.isfinite(points).all():
            row = int(np.flatnonzero(~np.isfinite(points).all(axis=1))[0])
            _fail(f'{name}.mesh', f'vertex {row} of {path} is not finite '
                  f'({", ".join(str(c) for c in points[row])})', mesh)
        if np.abs(points).max(initial=0.0) > SIZE_RANGE[1]:
            _fail(f'{name}.mesh', f'vertices of {path} must be within {SIZE_RANGE[1]:g} m '
                  'of the body origin', mesh)
    else:
        if len(flat) % 3:
            _fail(f'{name}.points', 'needs x, y, z triples', flat)
        points = hull_vertices(np.array(flat, float).reshape(-1, 3))
    problem = hull_problem(points)
    if problem:
        _fail(f'{name}.{"mesh" if mesh else "points"}',
              f'convex needs at least 4 points spanning a volume: {problem}', mesh or flat)
    return tuple(tuple(float(c) for c in p) for p in points)


def ignored_pairs(entries: Iterable[str], names: list[str]) -> list[tuple[int, int]]:
    """Body index pairs of ``ignore_pairs`` entries "a:b" (ValueError: one line naming it)."""
    pairs = []
    for entry in entries:
        parts = [part.strip() for part in entry.split(PAIR_SEPARATOR)]
        if len(parts) != 2 or not all(parts):
            _fail('ignore_pairs', 'each entry must be "a:b", two body names', entry)
        for part in parts:
            if part not in names:
                _fail('ignore_pairs', f'body {_short(part)!r} is not in bodies', entry)
        if parts[0] == parts[1]:
            _fail('ignore_pairs', 'an entry names one body twice', entry)
        a, b = names.index(parts[0]), names.index(parts[1])
        pairs.append((min(a, b), max(a, b)))
    return pairs


def collision_filter_of(values: Mapping[str, Any], names: list[str],
                        also: Iterable[tuple[str, str]] = ()) -> CollisionFilter:
    """The collision filter of validated values: per-body bits, ``ignore_pairs`` and
    ``also`` (pairs of body names, e.g. a robot's links)."""
    return CollisionFilter(
        tuple(values[f'body.{n}.collision_group'] for n in names),
        tuple(values[f'body.{n}.collision_mask'] for n in names),
        tuple(ignored_pairs(values['ignore_pairs'], names))
        + tuple((names.index(a), names.index(b)) for a, b in also))


def _shape(key: str, values: Mapping[str, Any], base_dir: Optional[Path], files: bool,
           static: bool) -> tuple[tuple[float, ...], tuple[tuple[float, float, float], ...]]:
    """Validated size and convex vertices of the one shape under ``key`` (a body or a
    piece: ``key.shape``, ``key.size``, ``key.mesh``, ``key.points``)."""
    shape = values[f'{key}.shape']
    size = values[f'{key}.size']
    points: tuple[tuple[float, float, float], ...] = ()
    if shape == 'convex':
        points = _convex_points(key, values, base_dir, files)
    else:
        what, count = SIZES[shape]
        _vector(f'{key}.size', size, count, what)
        if shape == 'plane':
            if not any(size[:3]):
                _fail(f'{key}.size', 'plane normal [nx, ny, nz] must be non-zero', size)
            if not static:
                _fail(f'{key}.static', 'a plane must be static', static)
        elif min(size) <= 0.0:
            _fail(f'{key}.size', f'{shape} needs {count} values {what} > 0', size)
        elif not all(SIZE_RANGE[0] <= v <= SIZE_RANGE[1] for v in size):
            _fail(f'{key}.size', f'{shape} sizes must be in [{SIZE_RANGE[0]:g}, '
                  f'{SIZE_RANGE[1]:g}] m', size)
    if shape == 'plane' and not (abs(size[3]) <= POSITION_LIMIT
                                 and max(abs(v) for v in size[:3]) <= SIZE_RANGE[1]):
        _fail(f'{key}.size', f'plane needs |nx|, |ny|, |nz| <= {SIZE_RANGE[1]:g} and '
              f'|d| <= {POSITION_LIMIT:g} m', size)
    return (tuple(size) if shape != 'convex' else ()), points


def _unit_quaternion(name: str, value: list[float]) -> tuple[float, float, float, float]:
    """A validated orientation parameter, normalised (x, y, z, w)."""
    orientation = _vector(name, value, 4, '[x, y, z, w]')
    norm = math.sqrt(sum(c * c for c in orientation))
    if norm < 1e-6:
        _fail(name, 'quaternion must be non-zero', list(orientation))
    return tuple(c / norm for c in orientation)  # type: ignore[return-value]


def _pieces(key: str, values: Mapping[str, Any], base_dir: Optional[Path], files: bool,
            given: set[str]) -> tuple[Piece, ...]:
    """The validated pieces of a compound body (``key.shapes``), from
    ``key.piece.<piece>.*``; the body's own shape parameters must not be given."""
    for param in ('shape', 'size', 'mesh', 'points', 'decompose'):
        if f'{key}.{param}' in given and values[f'{key}.{param}'] is not False:
            _fail(f'{key}.{param}', f'a compound body ({key}.shapes) takes its shape from its '
                  'pieces: set it per piece', values[f'{key}.{param}'])
    pieces = []
    for name in values[f'{key}.shapes']:
        at = f'{key}.piece.{name}'
        size, points = _shape(at, values, base_dir, files, True)
        pieces.append(Piece(name, values[f'{at}.shape'], size, points,
                            _vector(f'{at}.position', values[f'{at}.position'], 3,
                                    '[x, y, z]'),
                            _unit_quaternion(f'{at}.orientation', values[f'{at}.orientation'])))
    return tuple(pieces)


def _decomposed(key: str, values: Mapping[str, Any], base_dir: Optional[Path],
                files: bool) -> tuple[Piece, ...]:
    """The pieces (``hull_<k>``) of a decomposed mesh body: from the cache beside the mesh,
    or made now (``core.decomposition``)."""
    mesh = values[f'{key}.mesh']
    if values[f'{key}.shape'] != 'convex' or not mesh:
        _fail(f'{key}.decompose', 'needs shape convex with a mesh', True)
    if not files:
        _fail(f'{key}.decompose', 'a recorded scene carries its hulls (shapes), it names no '
              'file: a mesh path from a bag is not read', mesh)
    path = Path(mesh) if Path(mesh).is_absolute() else (base_dir or Path.cwd()) / mesh
    try:
        hulls = decomposition.hulls(path, _mesh_bytes(path), values[f'{key}.decompose_threshold'],
                                    values[f'{key}.decompose_max_hulls'])
    except (OSError, ValueError, struct.error) as error:
        reason = error.strerror if isinstance(error, OSError) and error.strerror \
            else str(error)
        _fail(f'{key}.mesh', f'cannot decompose mesh {path} ({reason})', mesh)
    return tuple(Piece(f'hull_{k}', 'convex', (), tuple(tuple(float(c) for c in p) for p in h))
                 for k, h in enumerate(hulls))


def _triangle_mesh(key: str, values: Mapping[str, Any], base_dir: Optional[Path], files: bool,
                   static: bool) -> tuple[tuple[float, float, float], ...]:
    """The corners (three a triangle) of a triangle-mesh body: its mesh file's triangles, or
    ``key.points`` (nine values a triangle, as a recorded scene carries them); static only."""
    if not static:
        _fail(f'{key}.static', 'a triangle_mesh must be static (scenery: a surface has no '
              'mass)', static)
    mesh, flat = values[f'{key}.mesh'], values[f'{key}.points']
    if mesh:
        path, corners = _mesh_file(key, mesh, base_dir, files, 'triangles', lambda path: (
            mesh_surface(_mesh_bytes(path), path.suffix, str(path)).reshape(-1, 3)))
        if np.abs(corners).max() > SIZE_RANGE[1]:
            _fail(f'{key}.mesh', f'vertices of {path} must be within {SIZE_RANGE[1]:g} m '
                  'of the body origin', mesh)
    else:
        if not flat or len(flat) % 9:
            _fail(f'{key}.points', 'a triangle_mesh needs a mesh, or points: nine values (three '
                  'corners) a triangle', flat)
        corners = np.array(flat, float).reshape(-1, 3)
        try:
            triangle_corners(BodySpec(key, TRIANGLE_MESH, static=True, points=corners))
        except ValueError as error:
            _fail(f'{key}.points', str(error).split(': ', 1)[1], flat)
    return tuple(tuple(float(c) for c in p) for p in corners)


def _body(name: str, values: Mapping[str, Any], base_dir: Optional[Path], files: bool = True,
          given: frozenset[str] = frozenset()) -> tuple[BodySpec, np.ndarray]:
    """BodySpec and the 13-vector initial state of body ``name`` from validated values
    (``given``: the names the input set, to tell a compound's stray shape parameter)."""
    key = f'body.{name}'
    static = values[f'{key}.static'] or values[f'{key}.kinematic']   # kinematic: static too
    shape, size, points, pieces = values[f'{key}.shape'], (), (), ()
    if values[f'{key}.shapes']:
        shape, pieces = COMPOUND, _pieces(key, values, base_dir, files, set(given))
    elif values[f'{key}.decompose']:
        shape, pieces = COMPOUND, _decomposed(key, values, base_dir, files)
    elif shape == TRIANGLE_MESH:
        points = _triangle_mesh(key, values, base_dir, files, static)
    else:
        size, points = _shape(key, values, base_dir, files, static)
    inertia = values[f'{key}.inertia']
    if inertia and (len(inertia) != 3 or min(inertia) <= 0.0):
        _fail(f'{key}.inertia', 'needs [ixx, iyy, izz] > 0, or [] to derive it', inertia)
    mu_s, mu_k = values[f'{key}.static_friction'], values[f'{key}.kinetic_friction']
    if mu_k > mu_s:
        _fail(f'{key}.kinetic_friction', f'must be <= static_friction {mu_s}', mu_k)
    position = _vector(f'{key}.position', values[f'{key}.position'], 3, '[x, y, z]')
    orientation = _unit_quaternion(f'{key}.orientation', values[f'{key}.orientation'])
    linear = _vector(f'{key}.linear_velocity', values[f'{key}.linear_velocity'], 3,
                     '[vx, vy, vz]')
    angular = _vector(f'{key}.angular_velocity', values[f'{key}.angular_velocity'], 3,
                      '[wx, wy, wz]')
    spec = BodySpec(name=name, shape=shape, size=size, static=static, mass=values[f'{key}.mass'],
                    inertia=tuple(inertia) if inertia else None,  # type: ignore[arg-type]
                    restitution=values[f'{key}.restitution'], static_friction=mu_s,
                    kinetic_friction=mu_k, points=points,
                    rolling_resistance=values[f'{key}.rolling_resistance'],
                    torsional_friction=values[f'{key}.torsional_friction'], pieces=pieces)
    if pieces and not static:
        try:
            centre_of_mass(spec, check=True)
        except ValueError as error:
            _fail(f'{key}.{"shapes" if values[f"{key}.shapes"] else "mesh"}',
                  str(error).split(': ', 1)[1], values[f'{key}.shapes'] or values[f'{key}.mesh'])
    state = np.array(position + orientation + linear + angular)
    return spec, state


def scene_from_values(values: Mapping[str, Any], base_dir: Optional[Path] = None,
                      files: bool = True) -> Scene:
    """Validate flat {dotted name: value} parameters into a Scene (ValueError: one line).

    Missing parameters take their defaults; ``None`` means not set. Unknown
    names are errors (a typo must not pass silently). ``files=False``: the
    values are untrusted (a bag's recorded params) and name no file to read.
    """
    raw = dict(values)
    listed = _typed(SCENE_PARAMS[1], raw.get('bodies'))
    links = _robot(raw, base_dir, files)
    if not listed and not links.links:
        _fail('bodies', 'at least one body name required', listed)
    for name in links.links:
        if name in listed:
            _fail('bodies', f'{name!r} is also a link of robot_description', listed)
    raw = {**links.values, **raw}   # a link's body.<link>.* set by the user wins
    bodies_value = list(listed) + list(links.links)
    for name in bodies_value:
        if not NAME_PATTERN.match(name):
            raise ValueError(f'bodies: name {_short(name)!r} must match {NAME_PATTERN.pattern} '
                             '(it is part of topic names)')
        if len(name) > NAME_MAX_LENGTH:
            raise ValueError(f'bodies: name {_short(name)!r} has {len(name)} characters, at '
                             f'most {NAME_MAX_LENGTH} (its topic '
                             f'{LONGEST_BODY_TOPIC.format("<name>")} must stay within '
                             f'{TOPIC_MAX_LENGTH} characters)')
    duplicates = sorted(n for n, count in Counter(bodies_value).items() if count > 1)
    if duplicates:
        _fail('bodies', f'duplicate name {duplicates[0]!r}', bodies_value)

    pieces = {}
    for body in bodies_value:
        key = f'body.{body}.shapes'
        names = _typed(body_param(body, _SHAPES), raw.get(key))
        for piece in names:
            if not NAME_PATTERN.match(piece) or len(piece) > NAME_MAX_LENGTH:
                _fail(key, f'piece name {_short(piece)!r} must match {NAME_PATTERN.pattern}',
                      names)
        if len(set(names)) != len(names):
            _fail(key, 'duplicate piece name', names)
        pieces[body] = names
    # (full name, spec of its kind): every body's parameters share their kind's spec
    named = [(name, spec) for name, spec, _ in named_specs(bodies_value, pieces)] \
        + [(spec.name, spec) for spec in SIM_PARAMS]
    known = {name for name, _ in named}
    for name in raw:
        if name in known or name in ROS_BUILTIN or name.startswith('qos_overrides.'):
            continue
        parts = name.split('.')
        if parts[0] == 'body' and len(parts) >= 3 and parts[1] not in bodies_value:
            _fail(name, f'body {parts[1]!r} is not in bodies', bodies_value)
        if parts[0] == 'body' and len(parts) >= 5 and parts[2] == 'piece' \
                and parts[3] not in pieces[parts[1]]:
            _fail(name, f'piece {parts[3]!r} is not in body.{parts[1]}.shapes',
                  pieces[parts[1]])
        if name == 'solver' and raw[name] is None:
            continue
        raise ValueError(f'{name}: unknown parameter')
    typed = _typed_values(named, raw)

    world_frame = typed['world_frame']
    if not world_frame:
        _fail('world_frame', 'must not be empty', world_frame)
    given = frozenset(name for name, value in raw.items() if value is not None)
    built = [_body(name, typed, base_dir, files, given) for name in bodies_value]
    collision_filter_of(typed, bodies_value)   # ValueError: a bad ignore_pairs entry
    state = np.array([s for _, s in built]).reshape(len(built), 13)
    initial = BodyStates(state[:, 0:3].copy(), state[:, 3:7].copy(), state[:, 7:10].copy(),
                         state[:, 10:13].copy())
    gravity = _vector('gravity', typed['gravity'], 3, '[gx, gy, gz]')
    solver = SolverSettings(**{f.name: typed[f'solver.{f.name}']
                               for f in fields(SolverSettings)})
    node = NodeSettings(**{f.name: typed[f.name] for f in fields(NodeSettings)})
    sim = SimSettings(gravity=gravity, rate_hz=typed['rate_hz'],  # type: ignore[arg-type]
                      duration=typed['duration'], publish_per_body=typed['publish_per_body'],
                      joint_motion=robot.joint_motion(typed['joint_motion'],
                                                      typed['robot_description']))
    typed['bodies'] = listed
    return Scene(world_frame, tuple(spec for spec, _ in built), initial, solver, node, sim,
                 typed, base_dir, links.ignored)


def _robot(raw: Mapping[str, Any], base_dir: Optional[Path], files: bool) -> robot.Robot:
    """The link bodies of ``robot_description`` (none when it is empty)."""
    spec = {s.name: s for s in SCENE_PARAMS}
    text = _typed(spec['robot_description'], raw.get('robot_description'))
    if not text:
        return robot.Robot('', (), {}, ())
    if not files:
        _fail('robot_description', 'a recorded scene carries its links as bodies, it names '
              'no file', _short(text))
    return robot.robot_from_urdf(text, base_dir, _read_mesh,
                                 _typed(spec['robot_self_collision'],
                                        raw.get('robot_self_collision')))


def scene_to_yaml(scene: Scene) -> str:
    """A complete params file of ``scene``: every parameter in one ``/**`` section.

    Loading it gives the same scene (a test checks it) with no other file
    needed: convex meshes are written as their vertices (``points``).
    """
    import yaml
    values = dict(scene.values)
    if scene.values.get('robot_description'):   # links written out as bodies, pairs too;
        # their recorded poses move them (no script without the URDF)
        values.update({'robot_description': '', 'robot_description_topic': False,
                       'joint_motion': [], 'bodies': scene.names,
                       'ignore_pairs': list(scene.values['ignore_pairs'])
                       + [f'{a}{PAIR_SEPARATOR}{b}' for a, b in scene.robot_ignored]})
    for body in scene.bodies:
        key = f'body.{body.name}'
        if body.shape in ('convex', TRIANGLE_MESH):
            values[f'{key}.mesh'] = ''
            values[f'{key}.points'] = [float(c) for p in body.points for c in p]
        if body.shape == COMPOUND:   # pieces written out whole: decomposed hulls too
            values = {name: value for name, value in values.items()
                      if not name.startswith(f'{key}.piece.')
                      and name not in {f'{key}.{p}' for p in ('shape', 'size', 'mesh', 'points',
                                                              'decompose')}}
            values[f'{key}.shapes'] = [piece.name for piece in body.pieces]
            for piece in body.pieces:
                at = f'{key}.piece.{piece.name}'
                values.update({f'{at}.shape': piece.shape, f'{at}.size': list(piece.size),
                               f'{at}.mesh': '',
                               f'{at}.points': [float(c) for p in piece.points for c in p],
                               f'{at}.position': list(piece.position),
                               f'{at}.orientation': list(piece.orientation)})
    nested: dict[str, Any] = {}
    for name, value in values.items():
        *path, leaf = name.split('.')
        target = nested
        for part in path:
            target = target.setdefault(part, {})
        target[leaf] = list(value) if isinstance(value, (tuple, list)) else value   # no aliases
    dumper = getattr(yaml, 'CSafeDumper', yaml.SafeDumper)   # libyaml: the same text, faster
    return yaml.dump({'/**': {'ros__parameters': nested}}, Dumper=dumper, sort_keys=False,
                     default_flow_style=None, width=99)


def with_changes(scene: Scene, changes: Mapping[str, Any]) -> Scene:
    """The scene with some runtime-changeable parameters changed (ValueError: one line).

    Only what changed is validated, by the same rules as a file (``_typed`` and the
    checks that involve it: kinetic <= static friction, ``ignore_pairs`` entries), and
    only the parts it touches are rebuilt: solver and node settings, a body's materials,
    the collision filter. The bodies' shapes stay as built at start (no mesh file is
    read again), and a parameter that shapes or places a body is refused as read-only.
    """
    specs = {spec.name: spec for spec in node_specs(scene.names, scene.pieces)}
    values = dict(scene.values)
    for name, value in changes.items():
        if name not in specs:
            raise ValueError(f'{_short(name, 100)}: unknown parameter')
        if not is_runtime_changeable(name):
            raise ValueError(f'{name}: read-only, fixed at start')
        values[name] = _typed(specs[name], value)
    bodies = list(scene.bodies)
    for k, body in enumerate(bodies):
        key = f'body.{body.name}'
        if not any(f'{key}.{m}' in changes for m in MATERIALS):
            continue
        mu_s, mu_k = values[f'{key}.static_friction'], values[f'{key}.kinetic_friction']
        if mu_k > mu_s:
            _fail(f'{key}.kinetic_friction', f'must be <= static_friction {mu_s}', mu_k)
        bodies[k] = replace(body, restitution=values[f'{key}.restitution'],
                            static_friction=mu_s, kinetic_friction=mu_k)
    collision_filter_of(values, scene.names)   # ValueError: a bad ignore_pairs entry
    solver = SolverSettings(**{f.name: values[f'solver.{f.name}']
                               for f in fields(SolverSettings)})
    node = NodeSettings(**{f.name: values[f.name] for f in fields(NodeSettings)})
    return replace(scene, bodies=tuple(bodies), solver=solver, node=node, values=values)


# --- documentation ----------------------------------------------------------------------------

def _default_text(spec: ParamSpec) -> str:
    value = spec.default
    if isinstance(value, bool):
        return 'true' if value else 'false'
    if isinstance(value, list):
        return '[' + ', '.join(str(v) for v in value) + ']'
    if isinstance(value, str):
        return f"'{value}'"
    return str(value)


# --- the node's declarations (rclpy types, imported when called) ------------------------------

def descriptor(spec: ParamSpec, read_only: bool) -> Any:
    """The ROS ParameterDescriptor of a ParamSpec (ranges from its minimum/maximum)."""
    from rcl_interfaces.msg import ParameterDescriptor
    kind, text, ranges = _described(spec.type, spec.description, spec.unit, spec.minimum,
                                    spec.maximum)
    d = ParameterDescriptor(name=spec.name, type=kind, description=text, read_only=read_only,
                            additional_constraints='one of: ' + range_text(spec)
                            if spec.choices else '')
    if ranges:
        setattr(d, *ranges)
    return d


@functools.lru_cache(maxsize=512)
def _described(kind: str, description: str, unit: str, minimum: Optional[float],
               maximum: Optional[float]) -> tuple[int, str, Optional[tuple[str, list[Any]]]]:
    """A descriptor's type, text and (range field, range) of a ParamSpec's fields: once per
    kind of parameter, not once per body (23,000 descriptors at 1000 bodies)."""
    from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterType
    types = {'double': ParameterType.PARAMETER_DOUBLE,
             'integer': ParameterType.PARAMETER_INTEGER,
             'bool': ParameterType.PARAMETER_BOOL, 'string': ParameterType.PARAMETER_STRING,
             'double_array': ParameterType.PARAMETER_DOUBLE_ARRAY,
             'string_array': ParameterType.PARAMETER_STRING_ARRAY}
    text = description + (f' [{unit}]' if unit else '')
    ranges = None
    if minimum is not None and maximum is not None:
        if kind == 'double':
            ranges = ('floating_point_range', [FloatingPointRange(
                from_value=float(minimum), to_value=float(maximum), step=0.0)])
        elif kind == 'integer':
            ranges = ('integer_range', [IntegerRange(from_value=int(minimum),
                                                     to_value=int(maximum), step=0)])
    return types[kind], text, ranges


def named_specs(body_names: Iterable[str] = (),
                pieces: Optional[Mapping[str, Iterable[str]]] = None
                ) -> Iterable[tuple[str, ParamSpec, str]]:
    """``(full name, spec, kind)`` of every parameter collres_node declares, in
    ``node_specs`` order, without renaming a spec per body: ``spec.name`` is the name within
    its kind (``restitution``), ``kind`` one name of that kind (``body.x.restitution``)."""
    for spec in SCENE_PARAMS:
        yield spec.name, spec, spec.name
    for name in body_names:
        for spec in BODY_PARAMS:
            yield f'body.{name}.{spec.name}', spec, f'body.x.{spec.name}'
        for piece in (pieces or {}).get(name, ()):
            for spec in PIECE_PARAMS:
                yield f'body.{name}.piece.{piece}.{spec.name}', spec, \
                    f'body.x.piece.y.{spec.name}'
    for spec in SOLVER_PARAMS:
        yield f'solver.{spec.name}', spec, f'solver.{spec.name}'
    for spec in NODE_PARAMS:
        yield spec.name, spec, spec.name


_PARAMETER_TYPES = {'double': 'DOUBLE', 'integer': 'INTEGER', 'bool': 'BOOL',
                    'string': 'STRING', 'double_array': 'DOUBLE_ARRAY',
                    'string_array': 'STRING_ARRAY'}


class DeclaredDescriptors(dict):
    """An rclpy node's ``_descriptors`` ({name: ParameterDescriptor}) whose scene
    descriptors are built when first read (``ros2 param describe``, a ``set``): ``pending``
    holds {name: the descriptor of its kind}, copied under the name on first read.
    Membership, reading, replacing and deleting behave as for the plain dict rclpy keeps
    (what rclpy does with it); iterating sees only those built."""

    def __init__(self, declared: Mapping[str, Any], pending: dict[str, Any]) -> None:
        super().__init__(declared)
        self._pending = pending

    def __missing__(self, name: str) -> Any:
        from rcl_interfaces.msg import ParameterDescriptor
        template = self._pending.pop(name)   # KeyError: not declared
        built = self[name] = ParameterDescriptor(
            check_fields=False, name=name, type=template.type,
            description=template.description, read_only=template.read_only,
            additional_constraints=template.additional_constraints,
            floating_point_range=list(template.floating_point_range),
            integer_range=list(template.integer_range))
        return built

    def __contains__(self, name: object) -> bool:
        return dict.__contains__(self, name) or name in self._pending

    def __setitem__(self, name: str, descriptor: Any) -> None:
        self._pending.pop(name, None)
        dict.__setitem__(self, name, descriptor)

    def __delitem__(self, name: str) -> None:
        if self._pending.pop(name, None) is None:
            dict.__delitem__(self, name)

    def get(self, name: str, default: Any = None) -> Any:
        return self[name] if name in self else default


def declare_scene(node: Any, scene: Scene) -> None:
    """Declare every parameter of ``scene`` (``named_specs``) on an rclpy node at once, with
    its validated value and its descriptor (``descriptor``: type, range, read-only when not
    ``is_runtime_changeable``); the node's parameter overrides are not read again.

    rclpy's ``declare_parameters`` sets and announces its declarations one at a time
    (building and publishing a ``/parameter_events`` message each: 23,000 declarations and
    3 s of start-up for a 1000-body scene). Here they are stored as rclpy stores them and
    not announced (nothing listens at start-up; every later change is announced by rclpy as
    usual); ``ros2 param list/get/describe/set`` see them as any declared parameter, and a
    later ``set`` is checked against the descriptor by rclpy. rclpy's check of the declared
    values against their descriptors is not run again: ``scene_from_values`` checked each
    against the same ``ParamSpec`` the descriptor is built from, inclusive bounds, as
    strict as rclpy's. The descriptors are built once per kind of parameter and copied
    under a name when first read (``DeclaredDescriptors``), and each ``Parameter`` is given
    its spec's type (rclpy checks that the value agrees): 0.6 s of a 1000-body start
    declared the slow way, 0.17 s of CPU with every descriptor copied at once, 0.07 s so.
    Raises ParameterAlreadyDeclaredException as ``declare_parameters`` does.
    """
    from rclpy.exceptions import ParameterAlreadyDeclaredException
    from rclpy.parameter import Parameter
    types = {kind: Parameter.Type[name] for kind, name in _PARAMETER_TYPES.items()}
    values = scene.values
    templates: dict[str, Any] = {}
    pending: dict[str, Any] = {}
    parameters: dict[str, Any] = {}
    for name, spec, kind in named_specs(scene.names, scene.pieces):
        template = templates.get(kind)
        if template is None:
            template = templates[kind] = descriptor(spec, not is_runtime_changeable(kind))
            template.type = types[spec.type].value
        value = values[name]
        if isinstance(value, tuple):
            value = list(value)
        parameters[name] = Parameter(name, types[spec.type], value) if value != [] \
            else Parameter(name, Parameter.Type.NOT_SET, None)   # an empty array: not set
        pending[name] = template
    again = [name for name in parameters if node.has_parameter(name)]
    if again:
        raise ParameterAlreadyDeclaredException(again)
    # what rclpy's declaration stores
    node._descriptors = DeclaredDescriptors(node._descriptors, pending)
    node._parameters.update(parameters)


def plain_value(value: Any) -> Any:
    """rclpy parameter value -> plain Python (arrays as lists)."""
    if isinstance(value, (array.array, tuple)):
        return list(value)
    return value


def markdown_table() -> str:
    """The README's parameter table (Markdown), generated from core/config.py."""
    sections = (
        ('`/**` (shared by collres_node and collres_sim)', list(SCENE_PARAMS)
         + [replace(s, name=f'body.<name>.{s.name}') for s in BODY_PARAMS]
         + [replace(s, name=f'body.<name>.piece.<piece>.{s.name}') for s in PIECE_PARAMS]),
        ('`collres_node`', [replace(s, name=f'solver.{s.name}') for s in SOLVER_PARAMS]
         + list(NODE_PARAMS)),
        ('`collres_sim`', list(SIM_PARAMS)),
    )
    lines = []
    for title, specs in sections:
        lines += ['', f'Section {title}:', '',
                  '| parameter | type | default | range | unit | runtime | description |',
                  '|---|---|---|---|---|---|---|']
        for spec in specs:
            runtime = 'yes' if is_runtime_changeable(spec.name.replace('<name>', 'x')) \
                and not title.startswith('`collres_sim') else 'no'
            text = spec.description + (f' ({spec.reason})' if spec.reason else '')
            lines.append(f'| `{spec.name}` | {spec.type} | `{_default_text(spec)}` | '
                         f'{range_text(spec).replace("|", "or")} | {spec.unit} | {runtime} | '
                         f'{text.replace("|", "/")} |')
    return '\n'.join(lines[1:]) + '\n'


if __name__ == '__main__':
    print(markdown_table(), end='')
