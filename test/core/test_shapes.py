"""Shapes: inertia against textbook formulas and numerical integration, bounds, mesh files."""

from __future__ import annotations

import itertools
import math
import struct

import numpy as np
import pytest

from collres_ros.core.shapes import (bounding_radius, collision_numbers, inertia_tensor,
                                     load_mesh_points, make_geometry, mass_properties,
                                     shape_offset)
from collres_ros.core.types import BodySpec


def grid_inertia(inside, half: float, cells: int = 120) -> tuple[np.ndarray, np.ndarray]:
    """Centre of mass (3,) and inertia (3, 3) about the origin of a unit-mass solid,
    by midpoint integration over the cube [-half, half]^3."""
    axis = (np.arange(cells) + 0.5) / cells * 2 * half - half
    x, y, z = np.meshgrid(axis, axis, axis, indexing='ij')
    mask = inside(x, y, z)
    p = np.stack((x[mask], y[mask], z[mask]), axis=1)
    centre = p.mean(axis=0)
    inertia = (np.sum(p * p) * np.eye(3) - p.T @ p) / p.shape[0]
    return centre, inertia


def test_inertia_of_each_shape_matches_the_textbook_formula() -> None:
    m = 2.5
    r, h = 0.2, 0.6
    cases = {
        'sphere': (BodySpec('s', 'sphere', (r,), mass=m), [0.4 * m * r * r] * 3),
        'box': (BodySpec('b', 'box', (0.2, 0.4, 0.6), mass=m),
                [m * (0.16 + 0.36) / 12, m * (0.04 + 0.36) / 12, m * (0.04 + 0.16) / 12]),
        'cylinder': (BodySpec('c', 'cylinder', (r, h), mass=m),
                     [m * (3 * r * r + h * h) / 12] * 2 + [0.5 * m * r * r]),
        'cone': (BodySpec('k', 'cone', (r, h), mass=m),
                 [m * (3 * r * r / 20 + 3 * h * h / 80)] * 2 + [0.3 * m * r * r]),
    }
    for name, (spec, expected) in cases.items():
        inertia = inertia_tensor(spec)
        print(name, np.diag(inertia), expected)
        np.testing.assert_allclose(np.diag(inertia), expected, rtol=1e-12, err_msg=name)
        np.testing.assert_allclose(inertia - np.diag(np.diag(inertia)), 0.0, atol=1e-15)


def test_capsule_and_cone_inertia_agree_with_numerical_integration() -> None:
    r, h = 0.1, 0.3

    def capsule(x, y, z):
        zc = np.clip(z, -h / 2, h / 2)
        return x * x + y * y + (z - zc) ** 2 <= r * r

    def cone(x, y, z):   # base at z = -h/4, apex at z = 3h/4: the body origin is the COM
        height = 0.75 * h - z
        return (z >= -0.25 * h) & (height >= 0) & (np.hypot(x, y) <= r * height / h)

    for name, inside, half in (('capsule', capsule, r + h / 2), ('cone', cone, 0.75 * h)):
        centre, numeric = grid_inertia(inside, half)
        expected = inertia_tensor(BodySpec(name, name, (r, h), mass=1.0))
        print(name, 'com', centre, 'numeric', np.diag(numeric), 'formula', np.diag(expected))
        np.testing.assert_allclose(centre, 0.0, atol=2e-3 * h)   # origin = centre of mass
        np.testing.assert_allclose(np.diag(numeric), np.diag(expected), rtol=1e-2)


def test_cone_geometry_is_shifted_so_the_body_origin_is_its_centre_of_mass() -> None:
    spec = BodySpec('k', 'cone', (0.1, 0.4))
    geometry = make_geometry(spec)
    coal_centre = np.asarray(geometry.computeCOM())   # coal: origin mid-axis, COM below it
    np.testing.assert_allclose(coal_centre + shape_offset(spec), 0.0, atol=1e-12)
    assert bounding_radius(spec) == pytest.approx(0.3)   # apex at 3/4 of the length


def test_convex_from_cube_corners_has_the_box_inertia() -> None:
    corners = tuple(itertools.product((-0.1, 0.1), (-0.2, 0.2), (-0.3, 0.3)))
    convex = inertia_tensor(BodySpec('c', 'convex', mass=3.0, points=corners))
    box = inertia_tensor(BodySpec('b', 'box', (0.2, 0.4, 0.6), mass=3.0))
    np.testing.assert_allclose(convex, box, atol=1e-12)


def test_off_centre_convex_inertia_is_about_the_body_origin() -> None:
    shift = np.array([0.5, 0.0, 0.0])
    corners = [tuple(np.array(c) + shift) for c in itertools.product((-0.1, 0.1), repeat=3)]
    inertia = inertia_tensor(BodySpec('c', 'convex', mass=1.0, points=tuple(corners)))
    about_com = 1.0 * (0.04 + 0.04) / 12
    np.testing.assert_allclose(np.diag(inertia), [about_com, about_com + 0.25,
                                                  about_com + 0.25], rtol=1e-9)


def test_static_bodies_have_zero_inverse_mass_and_inertia() -> None:
    for spec in (BodySpec('f', 'box', (1, 1, 1), static=True),
                 BodySpec('p', 'plane', (0, 0, 1, 0), static=True)):
        inverse_mass, inverse_inertia = mass_properties(spec)
        assert inverse_mass == 0.0 and not np.any(inverse_inertia)


def test_given_inertia_overrides_the_shape_and_zero_moments_are_guarded() -> None:
    inverse_mass, inverse = mass_properties(BodySpec('b', 'box', (1, 1, 1), mass=4.0,
                                                     inertia=(2.0, 0.0, 0.5)))
    assert inverse_mass == 0.25
    np.testing.assert_allclose(inverse, np.diag([0.5, 0.0, 2.0]), atol=1e-12)
    assert np.all(np.isfinite(inverse))


def test_bounding_radius_holds_every_vertex() -> None:
    assert bounding_radius(BodySpec('b', 'box', (0.2, 0.4, 0.4))) == pytest.approx(0.3)
    assert bounding_radius(BodySpec('c', 'capsule', (0.1, 0.4))) == pytest.approx(0.3)
    assert bounding_radius(BodySpec('y', 'cylinder', (0.3, 0.8))) == pytest.approx(0.5)
    assert math.isinf(bounding_radius(BodySpec('p', 'plane', (0, 0, 1, 0), static=True)))
    points = np.random.default_rng(1).normal(size=(30, 3))
    spec = BodySpec('v', 'convex', points=tuple(map(tuple, points)))
    assert bounding_radius(spec) == pytest.approx(np.max(np.linalg.norm(points, axis=1)))


def test_bad_sizes_are_refused_with_the_body_name() -> None:
    bad = [BodySpec('wheel', 'cylinder', (0.1,)),
           BodySpec('flat', 'convex', points=((0, 0, 0), (1, 0, 0), (0, 1, 0), (1, 1, 0))),
           BodySpec('ground', 'plane', (0, 0, 0, 1), static=True)]
    for spec in bad:   # the coal geometry and the numbers the compiled detector builds from
        with pytest.raises(ValueError, match=spec.name):
            make_geometry(spec)
        with pytest.raises(ValueError, match=spec.name):
            collision_numbers(spec)


def test_mesh_files_obj_and_stl_ascii_and_binary_give_the_cube_corners(tmp_path) -> None:
    corners = np.array(list(itertools.product((-0.5, 0.5), repeat=3)))
    faces = [(0, 1, 3), (0, 3, 2), (4, 6, 7), (4, 7, 5), (0, 4, 5), (0, 5, 1),
             (2, 3, 7), (2, 7, 6), (0, 2, 6), (0, 6, 4), (1, 5, 7), (1, 7, 3)]
    obj = tmp_path / 'cube.obj'
    obj.write_text(''.join(f'v {x} {y} {z}\n' for x, y, z in corners)
                   + ''.join(f'f {a + 1} {b + 1} {c + 1}\n' for a, b, c in faces))
    ascii_stl = tmp_path / 'cube_ascii.stl'
    ascii_stl.write_text('solid cube\n' + ''.join(
        'facet normal 0 0 0\nouter loop\n'
        + ''.join(f'vertex {x} {y} {z}\n' for x, y, z in corners[list(face)])
        + 'endloop\nendfacet\n' for face in faces) + 'endsolid cube\n')
    binary_stl = tmp_path / 'cube_binary.stl'
    records = b''.join(struct.pack('<12fH', 0, 0, 0, *corners[list(face)].ravel(), 0)
                       for face in faces)
    binary_stl.write_bytes(b'\0' * 80 + struct.pack('<I', len(faces)) + records)
    for path in (obj, ascii_stl, binary_stl):
        points = load_mesh_points(str(path))
        np.testing.assert_allclose(points, np.unique(corners, axis=0), err_msg=path.name)
