"""Collision detection against geometry: time of impact, tunnelling, manifolds, broad phase."""

from __future__ import annotations

import itertools
from dataclasses import replace
import math

import coal
import numpy as np
import pytest

from collres_ros.core import _native, rotation
from collres_ros.core.detection import Detection
from collres_ros.core.config import SOLVER_TUNING, SolverSettings
from collres_ros.core.types import BodySpec, ContactKind
from contacts import at_rest

SETTINGS = SolverSettings()
MARGIN_SPEED = next(spec.default for spec in SOLVER_TUNING if spec.name == 'margin_speed')
states = at_rest


def test_time_of_impact_of_two_approaching_spheres_matches_the_analytic_time() -> None:
    # r = 0.1 each; centres 1.0 apart close at 0.9 per step: touch at gap 0.2, t = 0.8 / 0.9
    world = Detection([BodySpec('a', 'sphere', (0.1,)), BodySpec('b', 'sphere', (0.1,))],
                      SETTINGS)
    contacts = world.detect(states([[-0.5, 0, 0], [0.5, 0, 0]]),
                            states([[-0.05, 0, 0], [0.05, 0, 0]]))
    assert contacts.count == 1 and contacts.kind[0] == ContactKind.IMPACT
    expected = 0.8 / 0.9
    print(f'toi {contacts.toi[0]:.6f} expected {expected:.6f}')
    assert abs(contacts.toi[0] - expected) <= SETTINGS.toi_tolerance
    assert contacts.toi[0] >= expected  # t1 side: overlapping at the reported time
    np.testing.assert_allclose(contacts.normal[0], [1, 0, 0], atol=1e-9)
    np.testing.assert_allclose(contacts.point[0], [0, 0, 0], atol=1e-3)
    assert contacts.depth[0] == pytest.approx(0.1, abs=1e-9)  # penetration at detection


def test_fast_small_sphere_through_a_thin_wall_is_caught_as_tunnelled() -> None:
    # 2 cm sphere at 200 m/s, 1 cm wall, 100 Hz: apart at both ends of the step
    world = Detection([BodySpec('wall', 'box', (0.01, 1.0, 1.0), static=True),
                       BodySpec('ball', 'sphere', (0.01,))], SETTINGS)
    before, after = states([[0, 0, 0], [-1.0, 0, 0]]), states([[0, 0, 0], [1.0, 0, 0]])
    contacts = world.detect(before, after)
    assert contacts.count == 1 and contacts.kind[0] == ContactKind.TUNNELLED
    expected = (1.0 - 0.005 - 0.01) / 2.0  # front face reached after 0.985 m of 2 m
    print(f'toi {contacts.toi[0]:.6f} expected {expected:.6f}')
    assert abs(contacts.toi[0] - expected) <= 2 * SETTINGS.toi_tolerance
    np.testing.assert_allclose(contacts.normal[0], [-1, 0, 0], atol=1e-6)  # wall -> ball
    assert contacts.point[0][0] == pytest.approx(-0.005, abs=1e-3)
    without_ccd = Detection(world.specs, SETTINGS.with_values(ccd=False))
    assert without_ccd.detect(before, after).count == 0  # the sweep is what catches it


def test_box_resting_face_down_gives_four_points_on_the_floor() -> None:
    for floor in (BodySpec('floor', 'plane', (0, 0, 1, 0), static=True),
                  BodySpec('floor', 'box', (10, 10, 0.2), static=True)):
        world = Detection([floor, BodySpec('box', 'box', (0.2, 0.4, 0.2))], SETTINGS)
        floor_z = 0.0 if floor.shape == 'plane' else -0.1
        resting = states([[0, 0, floor_z], [0, 0, 0.1 - 0.001]])
        contacts = world.detect(resting, resting)
        assert contacts.count == 4
        assert set(contacts.kind) == {ContactKind.PERSISTENT}
        np.testing.assert_allclose(contacts.normal, np.tile([0, 0, 1], (4, 1)), atol=1e-9)
        np.testing.assert_allclose(contacts.separation, -0.001, atol=1e-8)
        corners = sorted(map(tuple, np.round(contacts.point[:, :2], 6)))
        assert corners == sorted(itertools.product((-0.1, 0.1), (-0.2, 0.2)))
        assert len(set(contacts.feature)) == 4  # one id per corner, the same next step
        again = world.detect(resting, resting)
        assert list(again.feature) == list(contacts.feature)


def test_sphere_on_plane_depth_matches_geometry() -> None:
    world = Detection([BodySpec('floor', 'plane', (0, 0, 1, 0.5), static=True),
                       BodySpec('ball', 'sphere', (0.25,))], SETTINGS)
    state = states([[0, 0, 0], [0.3, -0.2, 0.5 + 0.25 - 0.0123]])
    contacts = world.detect(state, state)
    assert contacts.count == 1
    assert contacts.depth[0] == pytest.approx(0.0123, abs=1e-9)
    np.testing.assert_allclose(contacts.normal[0], [0, 0, 1], atol=1e-12)


def test_speculative_contact_within_margin_has_positive_separation() -> None:
    """A pair's margin is RESTING_MARGIN of the speculative margin while neither body moves,
    grown by how far each moves over the step, up to the speculative margin: a ball at rest
    4 mm above the floor has a speculative contact there, one at rest 8 mm above has none,
    and one that fell 10 mm over the step to 12 mm above has one again."""
    world = Detection([BodySpec('floor', 'plane', (0, 0, 1, 0), static=True),
                       BodySpec('ball', 'sphere', (0.1,))], SETTINGS)
    resting = _native.RESTING_MARGIN * SETTINGS.speculative_margin
    assert 0.004 < resting < 0.008
    state = states([[0, 0, 0], [0, 0, 0.1 + 0.004]])
    contacts = world.detect(state, state)
    assert contacts.count == 1 and contacts.kind[0] == ContactKind.PERSISTENT
    assert contacts.separation[0] == pytest.approx(0.004, abs=1e-9)
    still = states([[0, 0, 0], [0, 0, 0.1 + 0.008]])
    assert world.detect(still, still).count == 0
    above = states([[0, 0, 0], [0, 0, 0.1 + 0.022]])
    fell = states([[0, 0, 0], [0, 0, 0.1 + 0.012]])
    assert resting + 0.010 > 0.012
    contacts = world.detect(above, fell)
    assert contacts.count == 1 and contacts.kind[0] == ContactKind.PERSISTENT
    assert contacts.separation[0] == pytest.approx(0.012, abs=1e-9)
    far = states([[0, 0, 0], [0, 0, 0.1 + 2 * SETTINGS.speculative_margin]])
    assert world.detect(far, far).count == 0


def test_resting_margin_grows_with_the_step() -> None:
    """A pair at rest keeps at least MARGIN_SPEED times the step's dt of the margin (a gap
    it closes within the step at that speed), up to the speculative margin: a ball at rest
    8 mm above the floor has a speculative contact at a step whose dt brings that to
    10 mm, none at one that brings it to 4 mm (the resting quarter then holds)."""
    world = Detection([BodySpec('floor', 'plane', (0, 0, 1, 0), static=True),
                       BodySpec('ball', 'sphere', (0.1,))], SETTINGS)
    still = states([[0, 0, 0], [0, 0, 0.1 + 0.008]])
    assert _native.RESTING_MARGIN * SETTINGS.speculative_margin < 0.008
    contacts = world.detect(still, still, dt=0.010 / MARGIN_SPEED)
    assert contacts.count == 1 and contacts.kind[0] == ContactKind.PERSISTENT
    assert contacts.separation[0] == pytest.approx(0.008, abs=1e-9)
    assert world.detect(still, still, dt=0.004 / MARGIN_SPEED).count == 0
    far = states([[0, 0, 0], [0, 0, 0.1 + 0.022]])
    assert world.detect(far, far, dt=1.0).count == 0


def test_convex_hull_of_a_cube_collides_like_the_box() -> None:
    corners = tuple(itertools.product((-0.1, 0.1), repeat=3))
    floor = BodySpec('floor', 'plane', (0, 0, 1, 0), static=True)
    tilt = rotation.normalize(np.array([0.1, 0.2, 0.0, 1.0]))
    state = states([[0, 0, 0], [0, 0, 0.12]], [[0, 0, 0, 1], tilt])
    results = []
    for body in (BodySpec('c', 'box', (0.2, 0.2, 0.2)), BodySpec('c', 'convex', points=corners)):
        contacts = Detection([floor, body], SETTINGS).detect(state, state)
        results.append((contacts.count, np.sort(contacts.separation)))
    assert results[0][0] == results[1][0] >= 1
    np.testing.assert_allclose(results[0][1], results[1][1], atol=1e-6)


def test_broad_phase_finds_the_same_pairs_as_all_pairs() -> None:
    rng = np.random.default_rng(7)
    count = 200
    shapes = [BodySpec(f'b{i}', 'sphere', (0.05,)) if i % 2 else
              BodySpec(f'b{i}', 'box', (0.08, 0.08, 0.08)) for i in range(count)]
    world = Detection(shapes, SETTINGS)
    before = states(rng.uniform(0, 1.2, (count, 3)))
    after = before.copy()
    after.position += rng.normal(0, 0.03, (count, 3))
    found = set(world.candidate_pairs(before, after))
    radius = np.array([0.05 if i % 2 else math.sqrt(3) * 0.04 for i in range(count)])
    lo = np.minimum(before.position, after.position) - radius[:, None]
    hi = np.maximum(before.position, after.position) + radius[:, None]
    margin = SETTINGS.speculative_margin
    brute = {(i, j) for i, j in itertools.combinations(range(count), 2)
             if np.all(lo[i] - 0.5 * margin <= hi[j] + 0.5 * margin)
             and np.all(lo[j] - 0.5 * margin <= hi[i] + 0.5 * margin)}
    print(f'{len(found)} broad-phase pairs, {len(brute)} by bounding spheres')
    assert len(brute) > 50
    # the broad phase uses oriented boxes, tighter than bounding spheres, and is sound:
    # every pair within the margin at either end of the step is a candidate (checked
    # exactly on the sphere-sphere pairs)
    assert found <= brute
    close = set()
    for state in (before, after):
        for i, j in itertools.combinations(range(1, count, 2), 2):
            gap = np.linalg.norm(state.position[i] - state.position[j]) - radius[i] - radius[j]
            if gap <= margin:
                close.add((i, j))
    print(f'{len(close)} sphere pairs within the margin')
    assert len(close) > 5 and close <= found


def test_every_shape_detects_resting_on_the_floor() -> None:
    floor = BodySpec('floor', 'box', (4, 4, 0.2), static=True)
    cases = [('sphere', (0.1,), 0.1), ('box', (0.2, 0.2, 0.3), 0.15),
             ('capsule', (0.1, 0.3), 0.25), ('cylinder', (0.1, 0.3), 0.15),
             ('cone', (0.1, 0.4), 0.1)]  # cone origin: centre of mass, a quarter up the axis
    for shape, size, half_height in cases:
        world = Detection([floor, BodySpec('b', shape, size)], SETTINGS)
        state = states([[0, 0, -0.1], [0, 0, half_height - 0.002]])
        contacts = world.detect(state, state)
        assert contacts.count >= 1, shape
        print(shape, contacts.count, contacts.separation)
        np.testing.assert_allclose(contacts.separation, -0.002, atol=2e-4, err_msg=shape)
        np.testing.assert_allclose(contacts.normal[:, 2], 1.0, atol=1e-6, err_msg=shape)


def polygon_area(points: np.ndarray) -> float:
    """Area (m^2) of the convex hull of points on a horizontal plane (x, y used)."""
    xy = points[:, :2]
    centre = xy.mean(axis=0)
    order = np.argsort(np.arctan2(xy[:, 1] - centre[1], xy[:, 0] - centre[0]))
    x, y = xy[order, 0], xy[order, 1]
    return 0.5 * abs(float(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1))))


def test_box_on_a_turned_box_keeps_four_points_that_span_most_of_the_patch() -> None:
    # a cube turned 0.7 rad about z on another: the faces overlap in an octagon (8 points)
    lower = BodySpec('lower', 'box', (0.2, 0.2, 0.2))
    upper = BodySpec('upper', 'box', (0.2, 0.2, 0.2))
    turned = rotation.from_rotation_vector(np.array([0.0, 0.0, 0.7]))
    state = states([[0, 0, 0], [0.02, 0, 0.199]], [[0, 0, 0, 1], turned])
    world = Detection([lower, upper], SETTINGS)
    contacts = world.detect(state, state)
    # the full patch from coal itself
    rotations = rotation.to_matrix(state.orientation)
    poses = [coal.Transform3s(r, p) for r, p in zip(rotations, state.position)]
    request, result = coal.CollisionRequest(), coal.CollisionResult()
    request.security_margin = SETTINGS.speculative_margin
    geometries = [coal.Box(0.2, 0.2, 0.2), coal.Box(0.2, 0.2, 0.2)]
    coal.collide(geometries[0], poses[0], geometries[1], poses[1], request, result)
    patch_request, patches = coal.ContactPatchRequest(), coal.ContactPatchResult()
    patch_request.setPatchTolerance(0.01)
    coal.computeContactPatch(geometries[0], poses[0], geometries[1], poses[1], result,
                             patch_request, patches)
    patch = patches.getContactPatch(0)
    full = np.array([patch.getPoint(k) for k in range(patch.size())])
    kept = polygon_area(contacts.point) / polygon_area(full)
    print(f'{patch.size()} patch points -> {contacts.count} contacts keeping {kept:.3f} '
          'of the patch area')
    assert patch.size() == 8 and contacts.count == 4
    assert kept >= 0.65   # the best quadrilateral in a regular octagon keeps 0.707
    assert len(set(contacts.feature)) == 4
    again = world.detect(state, state)
    assert list(again.feature) == list(contacts.feature)
    np.testing.assert_allclose(contacts.normal, np.tile([0, 0, 1], (4, 1)), atol=1e-9)


def test_the_manifold_of_two_overlapping_boxes_holds_their_depth() -> None:
    """Two cubes in random orientations, overlapping by 0-3 mm (coal's signed distance):
    the deepest row of their manifold is that depth, to within the slop. Where faces
    tilted to one another overlap, the patch is a polygon of up to eight points at
    different depths (the deepest where an edge of one cube crosses an edge of the other),
    and the reduction to four must keep the deepest; where the cubes cross edge on edge,
    the patch is a segment whose ends barely touch while the edges cross deep between
    them, and the manifold takes coal's own deepest point. On 1c15e3e 53 of these 300
    pairs were deeper than their manifold by more than the slop, by up to 15.9 mm (40 by
    more than 1 mm): a settling pile sank such corners and edges into one another
    unseen (300 mixed bodies: 4-14 mm at rest)."""
    cube = BodySpec('cube', 'box', (0.1, 0.1, 0.1))
    world = Detection([cube, replace(cube, name='other')], SETTINGS)
    geometry = coal.Box(0.1, 0.1, 0.1)
    rng = np.random.default_rng(5)

    def depth(turns: np.ndarray, position: np.ndarray) -> float:
        a, b = (coal.Transform3s(r, p) for r, p in
                zip(rotation.to_matrix(turns), [np.zeros(3), position]))
        return coal.distance(geometry, a, geometry, b, coal.DistanceRequest(),
                             coal.DistanceResult())

    missed = []
    for _ in range(300):
        turns = rotation.from_rotation_vector(rng.normal(size=(2, 3)) * 2.0)
        direction = rng.normal(size=3)
        direction /= np.linalg.norm(direction)
        # the second cube's centre along the direction where the cubes overlap the target
        target, near, far = -rng.uniform(0.0, 0.003), 0.0, 0.3
        for _ in range(60):
            middle = 0.5 * (near + far)
            near, far = (middle, far) if depth(turns, middle * direction) < target else \
                (near, middle)
        state = states([[0, 0, 0], near * direction], turns)
        contacts = world.detect(state, state)
        missed.append(float(contacts.separation.min()) - depth(turns, near * direction))
    print(f'deepest row above the true depth by {1e3 * max(missed):.3f} mm at most')
    assert max(missed) <= SETTINGS.linear_slop
