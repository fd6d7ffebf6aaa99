"""Collision shapes: validated sizes, coal geometries, mass properties and bounds of a BodySpec.

Conventions (see ``types.BodySpec``): the body frame is the shape frame and
its origin is the centre of mass. Every shape is centred on its origin except
the cone: coal puts a cone's origin at the middle of its axis, while its
centre of mass lies a quarter of the length above the base. Our cone's body
origin is its centre of mass, so its coal geometry sits at ``shape_offset``
(0, 0, +length/4) in the body frame: base at z = -length/4, apex at
z = +3 length/4. Sizes are in m, masses in kg, inertia in kg m^2.

A compound body (``types.COMPOUND``) is the union of its convex pieces, each a
shape of its own placed at its pose in the body frame. Its mass is spread
uniformly over the pieces' volumes (overlaps count twice, as in MuJoCo and
Drake); its centre of mass is theirs, and a dynamic compound body must have it
at the body origin (``centre_of_mass``; the params name the shift otherwise).

A triangle mesh (``types.TRIANGLE_MESH``) is static scenery that stays concave:
its triangles, each a one-sided piece of the compiled core, in the body frame.
"""

from __future__ import annotations

import math
import re
import struct
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from collres_ros.core.config import HULL_MAX_VERTICES
from collres_ros.core.rotation import to_matrix
from collres_ros.core.types import COMPOUND, TRIANGLE_MESH, BodySpec, Piece

if TYPE_CHECKING:
    import coal

# A dynamic compound body's centre of mass may lie this fraction of its bounding radius off
# its origin (a decomposed mesh's hulls overlap a little): the inertia is then taken about
# the origin, as a convex mesh's is. Farther off, the body frame must be moved.
CENTRE_TOLERANCE = 0.01


def make_geometry(spec: BodySpec) -> coal.CollisionGeometry:
    """A new coal geometry for ``spec`` (one instance per body: its id names the body)."""
    import coal   # here: its module takes 60 ms to import, and a node's start needs none
    size = [float(s) for s in spec.size]
    shape = spec.shape
    if shape == 'sphere':
        return coal.Sphere(_positive(spec, size, 1)[0])
    if shape == 'box':
        return coal.Box(*_positive(spec, size, 3))
    if shape == 'capsule':
        radius, length = _radius_length(spec, size)
        return coal.Capsule(radius, length)
    if shape == 'cylinder':
        radius, length = _radius_length(spec, size)
        return coal.Cylinder(radius, length)
    if shape == 'cone':
        radius, length = _radius_length(spec, size)
        return coal.Cone(radius, length)
    if shape == 'plane':
        normal, offset = plane_normal_offset(spec)
        return coal.Halfspace(normal, offset)
    if shape == 'convex':
        return convex_hull(convex_points(spec))
    if shape in (COMPOUND, TRIANGLE_MESH):
        raise ValueError(_ONE_PER_PIECE.format(spec.name))
    raise ValueError(f'{spec.name}: unknown shape {shape!r}')


_ONE_PER_PIECE = '{}: a compound body or a triangle mesh has a geometry per piece'


def collision_numbers(spec: BodySpec) -> tuple[list[float], list[float]]:
    """Validated sizes (m) and flat convex vertices (m, body frame) the compiled detector
    builds its coal geometry from (the same checks and messages as ``make_geometry``)."""
    size = [float(s) for s in spec.size]
    shape = spec.shape
    if shape == 'sphere':
        return _positive(spec, size, 1), []
    if shape == 'box':
        return _positive(spec, size, 3), []
    if shape in ('capsule', 'cylinder', 'cone'):
        return list(_radius_length(spec, size)), []
    if shape == 'plane':
        normal, offset = plane_normal_offset(spec)
        return [*normal.tolist(), offset], []
    if shape == 'convex':
        return [], convex_points(spec).reshape(-1).tolist()
    if shape in (COMPOUND, TRIANGLE_MESH):
        raise ValueError(_ONE_PER_PIECE.format(spec.name))
    raise ValueError(f'{spec.name}: unknown shape {shape!r}')


def shape_offset(spec: BodySpec) -> np.ndarray:
    """Position (3,) m of the coal geometry's origin in the body frame (non-zero for cones)."""
    if spec.shape == 'cone':
        return np.array([0.0, 0.0, 0.25 * float(spec.size[1])])
    return np.zeros(3)


def plane_normal_offset(spec: BodySpec) -> tuple[np.ndarray, float]:
    """Unit normal (3,) and offset d (m) of a plane spec: the solid half-space n.x <= d."""
    if len(spec.size) != 4:
        raise ValueError(f'{spec.name}: plane size must be [nx, ny, nz, d]')
    normal = np.array(spec.size[:3], dtype=float)
    length = float(np.linalg.norm(normal))
    if not length > 0.0 or not math.isfinite(length):
        raise ValueError(f'{spec.name}: plane normal must be non-zero and finite')
    return normal / length, float(spec.size[3]) / length


def convex_points(spec: BodySpec) -> np.ndarray:
    """Vertices (K, 3) m, body frame, of a convex spec: ValueError unless a hull can be built
    (at least 4 finite points spanning a volume, ``hull_problem``)."""
    points = np.asarray(spec.points, dtype=float).reshape(-1, 3)
    problem = hull_problem(points)
    if problem:
        raise ValueError(f'{spec.name}: convex {problem}')
    return points


def triangle_corners(spec: BodySpec) -> np.ndarray:
    """Corners (T, 3, 3) m, body frame, of a triangle mesh's triangles (front: a, b, c
    counter-clockwise): ValueError naming the first triangle that has no area, is not
    finite or lies beyond 1e9 m (the compiled core's ``triangle_problem``)."""
    from collres_ros.core import _native
    corners = np.asarray(spec.points, dtype=float).reshape(-1, 3)
    if len(corners) == 0 or len(corners) % 3:
        raise ValueError(f'{spec.name}: a triangle mesh needs three corners per triangle '
                         f'(got {len(corners)} points)')
    corners = corners.reshape(-1, 3, 3)
    for index, triangle in enumerate(corners):
        problem = _native.triangle_problem(triangle.reshape(-1).tolist())
        if problem:
            raise ValueError(f'{spec.name}: triangle {index}: {problem}')
    return corners


def mesh_surface(data: bytes, suffix: str, name: str = 'mesh') -> np.ndarray:
    """Corners (T, 3, 3), in the file's units, of the triangles of an OBJ or STL file that
    have an area (a sliver or a repeated corner touches nothing and is left out): a
    triangle mesh's surface. ValueError naming ``name`` when no such triangle remains."""
    from collres_ros.core import _native
    vertices, faces = mesh_triangles(data, suffix, name)
    corners = vertices[faces]
    if not np.isfinite(corners).all():
        raise ValueError(f'{name}: a vertex is not finite')
    kept = [not _native.triangle_problem(t.reshape(-1).tolist()) for t in corners]
    if not any(kept):
        raise ValueError(f'{name}: no triangle has an area')
    return corners[np.array(kept)]


def piece_names(spec: BodySpec) -> list[str]:
    """The names of a body's pieces by index, as contacts name them: a compound's pieces,
    a triangle mesh's ``triangle_<k>``, [''] for a body of one shape."""
    if spec.shape == TRIANGLE_MESH:
        return [f'triangle_{k}' for k in range(len(spec.points) // 3)]
    return [piece.name for piece in spec.pieces] or ['']


def hull_problem(points: np.ndarray) -> str:
    """Why coal cannot build a convex hull of (K, 3) points (m), or '' when it can.

    The compiled core's check (src/shapes.h): fewer than 4 points, a non-finite
    coordinate, or points on one spot, line or plane (flatter than
    ``_native.HULL_FLATNESS`` of their extent). qhull, under coal, kills the
    process on such a set, so every hull is built only after this check.
    """
    from collres_ros.core import _native
    return str(_native.hull_problem(np.asarray(points, dtype=float).reshape(-1).tolist()))


def convex_hull(points: np.ndarray) -> coal.Convex:
    """coal convex hull (with its triangles, so volume and inertia work) of (K, 3) points
    (ValueError when ``hull_problem`` finds none can be built)."""
    problem = hull_problem(points)
    if problem:
        raise ValueError(f'convex {problem}')
    import coal
    vertices = coal.StdVec_Vec3s()
    for point in np.asarray(points, dtype=float):
        vertices.append(point)
    return coal.ConvexBase.convexHull(vertices, True, 'Qt')


def mass_properties(spec: BodySpec) -> tuple[float, np.ndarray]:
    """(inverse mass 1/kg, inverse inertia (3, 3) 1/(kg m^2), body frame about the origin).

    Both are zero for static bodies (infinite mass). Solid shapes of uniform
    density; ``spec.inertia`` (principal moments) overrides the shape's. A
    zero principal moment gives a zero inverse on that axis (no division by 0).
    """
    if spec.shape == TRIANGLE_MESH and not spec.static:
        raise ValueError(f'{spec.name}: a triangle mesh must be static (it has no volume)')
    if spec.static or spec.shape == 'plane':
        return 0.0, np.zeros((3, 3))
    mass = float(spec.mass)
    if not mass > 0.0 or not math.isfinite(mass):
        raise ValueError(f'{spec.name}: mass must be positive and finite (got {mass})')
    if spec.shape == COMPOUND:
        centre_of_mass(spec, check=True)
    if spec.inertia is not None:
        inertia = np.diag(np.asarray(spec.inertia, dtype=float))
    else:
        inertia = inertia_tensor(spec)
    return 1.0 / mass, _guarded_inverse(inertia)


def inertia_tensor(spec: BodySpec) -> np.ndarray:
    """Inertia (3, 3) kg m^2 of the solid shape of mass ``spec.mass`` about the body origin."""
    m = float(spec.mass)
    size = [float(s) for s in spec.size]
    shape = spec.shape
    if shape == 'sphere':
        r = size[0]
        return np.diag([0.4 * m * r * r] * 3)
    if shape == 'box':
        x, y, z = (s * s for s in size[:3])
        return np.diag([m * (y + z), m * (x + z), m * (x + y)]) / 12.0
    if shape == 'cylinder':
        r, h = size[0], size[1]
        side = m * (3.0 * r * r + h * h) / 12.0
        return np.diag([side, side, 0.5 * m * r * r])
    if shape == 'cone':  # about the centre of mass, a quarter of the length above the base
        r, h = size[0], size[1]
        side = m * (3.0 * r * r / 20.0 + 3.0 * h * h / 80.0)
        return np.diag([side, side, 0.3 * m * r * r])
    if shape == 'capsule':
        r, h = size[0], size[1]
        cylinder_volume = math.pi * r * r * h
        balls_volume = 4.0 / 3.0 * math.pi * r ** 3
        mc = m * cylinder_volume / (cylinder_volume + balls_volume)
        mb = m - mc
        axial = 0.5 * mc * r * r + 0.4 * mb * r * r
        side = (mc * (h * h / 12.0 + r * r / 4.0)
                + mb * (0.4 * r * r + h * h / 4.0 + 3.0 * h * r / 8.0))
        return np.diag([side, side, axial])
    if shape == 'convex':
        hull = convex_hull(convex_points(spec))
        volume = float(hull.computeVolume())
        if not volume > 0.0:
            raise ValueError(f'{spec.name}: convex hull has no volume')
        centre = np.asarray(hull.computeCOM(), dtype=float)
        about_com = np.asarray(hull.computeMomentofInertiaRelatedToCOM()) * (m / volume)
        # parallel axis: inertia about the body origin, which is the declared centre of mass
        shift = m * (centre @ centre * np.eye(3) - np.outer(centre, centre))
        return 0.5 * (about_com + about_com.T) + shift
    if shape == COMPOUND:
        volumes, centres, inertias = _piece_solids(spec)
        masses = m * volumes / volumes.sum()
        about_origin = np.zeros((3, 3))
        for mass, centre, inertia in zip(masses, centres, inertias):
            # each piece about its own centre, then moved to the body origin (parallel axis)
            about_origin += mass * (inertia + centre @ centre * np.eye(3)
                                    - np.outer(centre, centre))
        return 0.5 * (about_origin + about_origin.T)
    raise ValueError(f'{spec.name}: no inertia for shape {shape!r}')


def piece_spec(body: BodySpec, piece: Piece) -> BodySpec:
    """A compound body's piece as a body of its own (body frame = the piece's shape frame),
    named ``body/piece`` in errors."""
    return BodySpec(name=f'{body.name}/{piece.name}', shape=piece.shape, size=piece.size,
                    points=piece.points)


def volume(spec: BodySpec) -> float:
    """Volume (m^3) of a solid single shape (ValueError for planes and compounds)."""
    size = [float(s) for s in spec.size]
    shape = spec.shape
    if shape == 'sphere':
        return 4.0 / 3.0 * math.pi * size[0] ** 3
    if shape == 'box':
        return size[0] * size[1] * size[2]
    if shape == 'cylinder':
        return math.pi * size[0] ** 2 * size[1]
    if shape == 'cone':
        return math.pi * size[0] ** 2 * size[1] / 3.0
    if shape == 'capsule':
        return math.pi * size[0] ** 2 * (size[1] + 4.0 / 3.0 * size[0])
    if shape == 'convex':
        return float(convex_hull(convex_points(spec)).computeVolume())
    raise ValueError(f'{spec.name}: no volume for shape {shape!r}')


def _piece_solids(spec: BodySpec) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per piece of a compound: volume (P,) m^3, centre (P, 3) m in the body frame and
    inertia per unit mass (P, 3, 3) m^2 about that centre, body axes."""
    volumes, centres, inertias = [], [], []
    for piece in spec.pieces:
        alone = piece_spec(spec, piece)
        rotation = to_matrix(np.asarray(piece.orientation, dtype=float))
        if piece.shape == 'convex':
            hull = convex_hull(convex_points(alone))
            size = float(hull.computeVolume())
            centre = np.asarray(hull.computeCOM(), dtype=float)
            inertia = np.asarray(hull.computeMomentofInertiaRelatedToCOM()) / size
        else:   # every other shape frame's origin is its centre of mass
            size, centre = volume(alone), np.zeros(3)
            inertia = inertia_tensor(alone)   # unit mass (BodySpec's default)
        volumes.append(size)
        centres.append(np.asarray(piece.position, dtype=float) + rotation @ centre)
        inertias.append(rotation @ (0.5 * (inertia + inertia.T)) @ rotation.T)
    return np.array(volumes), np.array(centres).reshape(-1, 3), np.array(inertias)


def centre_of_mass(spec: BodySpec, check: bool = False) -> np.ndarray:
    """Centre of mass (3,) m, body frame, of a compound body's pieces (uniform density).

    ``check``: ValueError, naming the shift that would put it there, unless it lies within
    ``CENTRE_TOLERANCE`` of the bounding radius of the body origin (the core's bodies turn
    about their origin).
    """
    volumes, centres, _ = _piece_solids(spec)
    centre = volumes @ centres / volumes.sum()
    if check and np.linalg.norm(centre) > CENTRE_TOLERANCE * bounding_radius(spec):
        shift = ', '.join(f'{-c:.6g}' for c in centre)
        raise ValueError(f'{spec.name}: the pieces\' centre of mass ('
                         f'{", ".join(f"{c:.6g}" for c in centre)}) m must be the body origin '
                         f'(a dynamic body turns about it): add ({shift}) to every piece\'s '
                         'position')
    return centre


def bounding_radius(spec: BodySpec) -> float:
    """Radius (m) of the smallest origin-centred sphere holding the shape (inf for planes)."""
    size = [float(s) for s in spec.size]
    shape = spec.shape
    if shape == 'sphere':
        return size[0]
    if shape == 'box':
        return 0.5 * math.sqrt(sum(s * s for s in size[:3]))
    if shape == 'capsule':
        return size[0] + 0.5 * size[1]
    if shape == 'cylinder':
        return math.hypot(size[0], 0.5 * size[1])
    if shape == 'cone':
        return max(0.75 * size[1], math.hypot(size[0], 0.25 * size[1]))
    if shape == 'plane':
        return math.inf
    if shape == 'convex':
        return float(np.max(np.linalg.norm(convex_points(spec), axis=1)))
    if shape == TRIANGLE_MESH:
        return float(np.max(np.linalg.norm(np.asarray(spec.points, float), axis=1)))
    if shape == COMPOUND:
        return max(float(np.linalg.norm(piece.position))
                   + bounding_radius(piece_spec(spec, piece)) for piece in spec.pieces)
    raise ValueError(f'{spec.name}: unknown shape {shape!r}')


def hull_vertices(points: np.ndarray, budget: int = HULL_MAX_VERTICES) -> np.ndarray:
    """Distinct vertices (K, 3) of a point set, at most ``budget``: a larger set is simplified
    to its vertices extreme along ``budget`` evenly spread directions (compiled core,
    ``_native.extreme_vertices``), whose hull approximates the full hull from inside
    (a 2,000,000-point sphere keeps 98 % of its volume). Finite points only."""
    from collres_ros.core import _native
    points = np.ascontiguousarray(points, dtype=float).reshape(-1, 3)
    if len(points) > budget:
        points = points[np.asarray(_native.extreme_vertices(points, budget), np.int64)]
    return np.unique(points, axis=0)


def load_mesh_points(path: str) -> np.ndarray:
    """Distinct vertices (K, 3) of an OBJ or STL (ASCII or binary) file, in the file's units."""
    return mesh_points(Path(path).read_bytes(), Path(path).suffix, str(path))


def mesh_points(data: bytes, suffix: str, name: str = 'mesh') -> np.ndarray:
    """Distinct vertices (K, 3) of the bytes of an OBJ or STL file (``suffix`` '.obj'/'.stl').

    The one mesh reader of the package (the params validator reads the bytes
    safely and parses them here). An STL is binary when its size is exactly
    84 + 50 * (the triangle count of its header), whatever its first bytes say
    (CAD tools write ``solid`` into binary headers too).
    """
    suffix = suffix.lower()
    if suffix == '.obj':
        points = _obj_vertices(data)
    elif suffix == '.stl':
        points = _stl_vertices(data)
    else:
        raise ValueError(f'{name}: unsupported mesh format (use .obj or .stl)')
    if points.shape[0] == 0:
        raise ValueError(f'{name}: no vertices found')
    if not np.isfinite(points).all():
        return np.unique(points, axis=0)   # the caller names the vertex that is not finite
    return hull_vertices(points)


def mesh_triangles(data: bytes, suffix: str, name: str = 'mesh'
                   ) -> tuple[np.ndarray, np.ndarray]:
    """The surface of an OBJ or STL file: vertices (K, 3) in the file's units and triangles
    (T, 3) int32 indices into them (OBJ polygons fanned; STL corners merged where equal).
    ValueError naming ``name`` when the file has no triangle or a face names no vertex."""
    suffix = suffix.lower()
    if suffix == '.obj':
        vertices = _obj_vertices(data)
        triangles = []
        for line in _OBJ_FACE.findall(data):
            try:
                corners = [int(token.split(b'/')[0]) for token in line.split()]
            except ValueError:
                raise ValueError(f'{name}: face {line[:60].decode(errors="replace")!r} is not '
                                 'vertex numbers') from None
            corners = [c - 1 if c > 0 else len(vertices) + c for c in corners]
            triangles += [(corners[0], corners[k], corners[k + 1])
                          for k in range(1, len(corners) - 1)]
        faces = np.array(triangles, dtype=np.int64).reshape(-1, 3)
    elif suffix == '.stl':
        corners = _stl_vertices(data)
        vertices, inverse = np.unique(corners, axis=0, return_inverse=True)
        faces = inverse.reshape(-1, 3)
    else:
        raise ValueError(f'{name}: unsupported mesh format (use .obj or .stl)')
    if faces.shape[0] == 0:
        raise ValueError(f'{name}: no triangles found')
    if faces.min() < 0 or faces.max() >= len(vertices):
        raise ValueError(f'{name}: a face names a vertex the file does not have')
    return np.ascontiguousarray(vertices, dtype=float), faces.astype(np.int32)


# a face line: `f a b c ...` (OBJ), each corner `v`, `v/t`, `v//n` or `v/t/n`
_OBJ_FACE = re.compile(rb'^[ \t]*f[ \t]+([^\r\n]+)', re.MULTILINE)
# a vertex line: `v x y z [w]` (OBJ), `vertex x y z` (ASCII STL); numbers as float() reads them
_OBJ_VERTEX = re.compile(rb'^[ \t]*v[ \t]+(\S+)[ \t]+(\S+)[ \t]+(\S+)', re.MULTILINE)
_STL_VERTEX = re.compile(rb'^[ \t]*vertex[ \t]+(\S+)[ \t]+(\S+)[ \t]+(\S+)', re.MULTILINE)


def _vertex_rows(pattern: re.Pattern[bytes], data: bytes) -> np.ndarray:
    rows = pattern.findall(data)
    try:
        return np.array(rows, dtype=float).reshape(-1, 3)
    except ValueError:
        bad = next(row for row in rows if not _numbers(row))
        raise ValueError(f'vertex {b" ".join(bad)[:60].decode(errors="replace")!r} is not '
                         'three numbers') from None


def _numbers(row: tuple[bytes, ...]) -> bool:
    try:
        [float(v) for v in row]
        return True
    except ValueError:
        return False


def _obj_vertices(data: bytes) -> np.ndarray:
    return _vertex_rows(_OBJ_VERTEX, data)


def _stl_vertices(data: bytes) -> np.ndarray:
    if len(data) >= 84:
        count = struct.unpack_from('<I', data, 80)[0]
        if len(data) == 84 + 50 * count:  # binary: 12 floats + 2 bytes per triangle
            records = np.frombuffer(data, dtype=np.dtype([('f', '<f4', (12,)), ('a', '<u2')]),
                                    count=count, offset=84)
            return records['f'][:, 3:].reshape(-1, 3).astype(float)
    return _vertex_rows(_STL_VERTEX, data)


def _positive(spec: BodySpec, size: list[float], count: int) -> list[float]:
    if len(size) < count or not all(s > 0.0 and math.isfinite(s) for s in size[:count]):
        raise ValueError(f'{spec.name}: {spec.shape} size needs {count} positive values')
    return size[:count]


def _radius_length(spec: BodySpec, size: list[float]) -> tuple[float, float]:
    radius, length = _positive(spec, size, 2)
    return radius, length


def _guarded_inverse(inertia: np.ndarray) -> np.ndarray:
    """Inverse of a symmetric inertia; axes with a non-positive moment get 0.

    A diagonal inertia (the primitives' principal moments) is inverted on its diagonal:
    what the eigen decomposition gives for it (unit eigenvectors, exact products), without
    its 50 us a body at start."""
    diagonal = np.diagonal(inertia)
    if not (inertia - np.diag(diagonal)).any():
        values, vectors = diagonal, None
    else:
        values, vectors = np.linalg.eigh(0.5 * (inertia + inertia.T))
    scale = max(float(np.max(np.abs(values))), 1e-300)
    inverse = np.where(values > 1e-12 * scale, 1.0 / np.where(values > 0.0, values, 1.0), 0.0)
    return np.diag(inverse) if vectors is None else (vectors * inverse) @ vectors.T
