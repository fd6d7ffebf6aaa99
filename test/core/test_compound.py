"""Compound bodies: mass, centre and inertia from the pieces against analytic results."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest

from collres_ros.core.shapes import (bounding_radius, centre_of_mass, inertia_tensor,
                                     make_geometry, mass_properties)
from collres_ros.core.types import COMPOUND, BodySpec, Piece


def box_inertia(m: float, x: float, y: float, z: float) -> np.ndarray:
    return np.diag([m * (y * y + z * z), m * (x * x + z * z), m * (x * x + y * y)]) / 12.0


def compound(*pieces: Piece, mass: float = 1.0, static: bool = False) -> BodySpec:
    return BodySpec('c', COMPOUND, mass=mass, static=static, pieces=pieces)


def test_two_boxes_side_by_side_are_one_box() -> None:
    m = 3.0
    body = compound(Piece('left', 'box', (0.2, 0.3, 0.5), position=(-0.1, 0.0, 0.0)),
                    Piece('right', 'box', (0.2, 0.3, 0.5), position=(0.1, 0.0, 0.0)), mass=m)
    np.testing.assert_allclose(centre_of_mass(body), 0.0, atol=1e-15)
    np.testing.assert_allclose(inertia_tensor(body), box_inertia(m, 0.4, 0.3, 0.5),
                               rtol=1e-12, atol=1e-15)


def test_a_dumbbell_of_two_spheres_and_a_cylinder() -> None:
    """Spheres r at x = +-d on a bar (cylinder a, length 2 d) turned onto the x axis."""
    m, r, a, d = 2.0, 0.1, 0.02, 0.3
    turn = (0.0, math.sin(math.pi / 4), 0.0, math.cos(math.pi / 4))   # z onto x
    body = compound(Piece('left', 'sphere', (r,), position=(-d, 0.0, 0.0)),
                    Piece('bar', 'cylinder', (a, 2 * d), orientation=turn),
                    Piece('right', 'sphere', (r,), position=(d, 0.0, 0.0)), mass=m)
    ball, bar = 4.0 / 3.0 * math.pi * r ** 3, math.pi * a * a * 2 * d
    ms, mc = m * ball / (2 * ball + bar), m * bar / (2 * ball + bar)
    axial = 2 * 0.4 * ms * r * r + 0.5 * mc * a * a
    across = 2 * (0.4 * ms * r * r + ms * d * d) + mc * (3 * a * a + (2 * d) ** 2) / 12.0
    np.testing.assert_allclose(inertia_tensor(body), np.diag([axial, across, across]),
                               rtol=1e-12, atol=1e-15)
    inverse_mass, inverse_inertia = mass_properties(body)
    assert inverse_mass == pytest.approx(1.0 / m)
    np.testing.assert_allclose(inverse_inertia, np.diag([1 / axial, 1 / across, 1 / across]),
                               rtol=1e-9)


def test_a_turned_piece_turns_its_inertia() -> None:
    """A box turned by 30 degrees about z: R I R^T, off-diagonal terms included."""
    m, angle = 1.5, math.radians(30.0)
    q = (0.0, 0.0, math.sin(angle / 2), math.cos(angle / 2))
    body = compound(Piece('only', 'box', (0.4, 0.1, 0.2), orientation=q), mass=m)
    c, s = math.cos(angle), math.sin(angle)
    rotation = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    expected = rotation @ box_inertia(m, 0.4, 0.1, 0.2) @ rotation.T
    assert abs(expected[0, 1]) > 1e-3
    np.testing.assert_allclose(inertia_tensor(body), expected, rtol=1e-12, atol=1e-15)


def test_a_convex_piece_off_its_own_origin_counts_at_its_centre() -> None:
    """A cube given by vertices around (0, 0, 0.1) in its frame, placed at z = -0.1: the
    body is that cube centred on the origin."""
    corners = [(x, y, 0.1 + z) for x, y, z in itertools.product((-0.05, 0.05), repeat=3)]
    body = compound(Piece('cube', 'convex', points=tuple(corners), position=(0, 0, -0.1)),
                    mass=2.0)
    np.testing.assert_allclose(centre_of_mass(body), 0.0, atol=1e-12)
    np.testing.assert_allclose(inertia_tensor(body), box_inertia(2.0, 0.1, 0.1, 0.1),
                               rtol=1e-9, atol=1e-15)


def test_an_l_shape_off_its_centre_of_mass_is_refused_when_dynamic() -> None:
    """An L of two equal boxes: its centre is between them; a dynamic body must turn about
    it, so the error names the shift; a static L is accepted as it is."""
    leg = Piece('leg', 'box', (0.1, 0.1, 0.3), position=(0.0, 0.0, 0.15))
    foot = Piece('foot', 'box', (0.3, 0.1, 0.1), position=(0.1, 0.0, -0.05))
    dynamic = compound(leg, foot)
    np.testing.assert_allclose(centre_of_mass(dynamic), [0.05, 0.0, 0.05], atol=1e-12)
    with pytest.raises(ValueError, match=r'add \(-0\.05, -0, -0\.05\)'):
        mass_properties(dynamic)
    assert mass_properties(compound(leg, foot, static=True))[0] == 0.0
    centred = compound(Piece('leg', 'box', (0.1, 0.1, 0.3), position=(-0.05, 0.0, 0.1)),
                       Piece('foot', 'box', (0.3, 0.1, 0.1), position=(0.05, 0.0, -0.1)))
    assert mass_properties(centred)[0] == pytest.approx(1.0)


def test_bounds_hold_every_piece_and_detection_refuses_compounds_clearly() -> None:
    body = compound(Piece('a', 'sphere', (0.1,), position=(0.3, 0.4, 0.0)),
                    Piece('b', 'box', (0.2, 0.2, 0.2)))
    assert bounding_radius(body) == pytest.approx(0.6)
    with pytest.raises(ValueError, match='a geometry per piece'):
        make_geometry(body)   # one per piece
