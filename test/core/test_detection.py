"""Detection: broad phase, rotational sweeps, the closest-points normal, stored manifolds,
frozen bodies. (Translational time of impact, tunnelling and manifolds: test_collision_laws.)"""

from __future__ import annotations

import itertools
import math

import coal
import numpy as np
import pytest

from collres_ros.core import _native, rotation
from collres_ros.core.detection import Detection
from collres_ros.core.config import SOLVER_TUNING, SolverSettings
from collres_ros.core.shapes import make_geometry
from collres_ros.core.types import BodySpec, BodyStates, ContactKind
from contacts import at_rest

SETTINGS = SolverSettings()
states = at_rest
REUSE_SHIFT = next(spec.default for spec in SOLVER_TUNING if spec.name == 'reuse_shift')
REUSE_LIMIT = REUSE_SHIFT * 0.1   # m: how far a pair of 0.2 m boxes may shift, reused
RESTING = _native.RESTING_MARGIN * SETTINGS.speculative_margin   # m: the margin of a pair at rest


def brute_pairs(lo: np.ndarray, hi: np.ndarray) -> set[tuple[int, int]]:
    """All pairs i < j of overlapping boxes, by testing every pair."""
    touch = np.all((lo[:, None, :] <= hi[None, :, :]) & (lo[None, :, :] <= hi[:, None, :]),
                   axis=2)
    i, j = np.nonzero(np.triu(touch, k=1))
    return set(zip(i.tolist(), j.tolist()))


def test_broad_phase_gives_exactly_the_overlapping_swept_boxes_over_moving_boxes() -> None:
    rng = np.random.default_rng(3)
    count = 200
    centre = rng.uniform(0.0, 1.0, (count, 3))
    half = rng.uniform(0.02, 0.08, (count, 3))
    world = Detection([BodySpec(f'b{k}', 'box', tuple(2 * half[k])) for k in range(count)],
                      SETTINGS)
    pad = 0.5 * SETTINGS.speculative_margin
    for step in range(6):   # small and large moves, boxes not turning: bounds are exact
        before = states(centre.copy())
        centre += rng.normal(0.0, 0.01 if step % 2 else 0.05, (count, 3))
        after = states(centre.copy())
        lo = np.minimum(before.position, after.position) - half - pad
        hi = np.maximum(before.position, after.position) + half + pad
        expected = brute_pairs(lo, hi)
        found = world.candidate_pairs(before, after)
        assert found == sorted(set(found)), step   # a < b, sorted, each pair once
        assert set(found) == expected, step
    print(f'{len(expected)} overlapping pairs of {count} boxes')
    assert len(expected) > 100


def test_broad_phase_misses_no_pair_that_every_pair_query_finds() -> None:
    rng = np.random.default_rng(5)
    count = 60
    specs = [BodySpec('floor', 'plane', (0, 0, 1, 0), static=True)] + [
        BodySpec(f'b{i}', ('sphere', 'box', 'capsule')[i % 3],
                 (0.05,) if i % 3 == 0 else (0.08, 0.06, 0.1) if i % 3 == 1 else (0.04, 0.1))
        for i in range(count)]
    before = states(np.r_[[[0, 0, 0]], rng.uniform([0, 0, 0.0], [0.8, 0.8, 0.6], (count, 3))])
    before.orientation[1:] = rotation.normalize(rng.normal(size=(count, 4)))
    after = before.copy()
    after.position[1:] += rng.normal(0, 0.02, (count, 3))
    contacts = Detection(specs, SETTINGS).detect(before, after)
    # every pair queried with coal at the current state, without any broad phase
    geometries = [make_geometry(spec) for spec in specs]
    rotations = rotation.to_matrix(after.orientation)
    poses = [coal.Transform3s(r, p) for r, p in zip(rotations, after.position)]
    request, result = coal.CollisionRequest(), coal.CollisionResult()
    request.security_margin = SETTINGS.speculative_margin
    near = {}
    for i, j in itertools.combinations(range(count + 1), 2):
        result.clear()
        if coal.collide(geometries[i], poses[i], geometries[j], poses[j], request, result):
            near[(i, j)] = result.getContact(0).penetration_depth
    found = set(zip(contacts.body_a.tolist(), contacts.body_b.tolist()))
    print(f'{contacts.count} contacts on {len(found)} pairs; {len(near)} pairs within the '
          f'margin by querying all {count * (count + 1) // 2} pairs')
    assert len(near) > 20
    assert set(near) <= found
    for a, b in found - set(near):   # found but not near now: hit during the step
        rows = (contacts.body_a == a) & (contacts.body_b == b)
        assert np.all(contacts.kind[rows] != ContactKind.PERSISTENT), (a, b)
    for (a, b), distance in near.items():   # one point: the same signed distance as coal
        rows = (contacts.body_a == a) & (contacts.body_b == b)
        if specs[a].shape == 'sphere' or specs[b].shape == 'sphere':
            if contacts.kind[rows][0] == ContactKind.PERSISTENT:
                assert contacts.separation[rows][0] == pytest.approx(distance, abs=1e-9)


def test_rows_of_curved_bodies_do_not_depend_on_the_steps_before() -> None:
    """Curved bodies never keep stored points, and a pair measured apart is left unqueried
    only while no motion since could have brought it within the margin: a detector that saw
    every step before gives the same rows, bit for bit, as a fresh one, while long bodies
    turn and drift into and out of contact."""
    rng = np.random.default_rng(11)
    count = 40
    specs = [BodySpec('floor', 'plane', (0, 0, 1, 0), static=True)] + [
        BodySpec(f'b{i}', ('sphere', 'capsule', 'cylinder')[i % 3],
                 (0.04,) if i % 3 == 0 else (0.02, 0.3) if i % 3 == 1 else (0.03, 0.2))
        for i in range(count)]
    current = states(np.r_[[[0, 0, 0]], rng.uniform([0, 0, 0.05], [0.6, 0.6, 0.4], (count, 3))])
    current.orientation[1:] = rotation.normalize(rng.normal(size=(count, 4)))
    world = Detection(specs, SETTINGS)
    fields = ('body_a', 'body_b', 'point', 'normal', 'separation', 'toi', 'kind', 'feature')
    met = set()
    for step in range(40):
        previous = current.copy()
        current.position[1:] += rng.normal(0, 0.004, (count, 3))
        current.orientation[1:] = rotation.normalize(
            current.orientation[1:] + rng.normal(0, 0.03, (count, 4)))
        kept = world.detect(previous, current)
        fresh = Detection(specs, SETTINGS).detect(previous, current)
        for name in fields:
            np.testing.assert_array_equal(getattr(kept, name), getattr(fresh, name),
                                          err_msg=f'{name}, step {step}')
        met |= set(zip(kept.body_a.tolist(), kept.body_b.tolist()))
    print(f'{len(met)} pairs met over the steps')
    assert len(met) > 30


def test_spinning_bar_sweeping_through_a_sphere_is_caught_at_the_analytic_angle() -> None:
    # a 1 m bar (half width w) turns 90 deg about z in one step; a ball of radius r sits at
    # 45 deg, 0.5 m out: apart at both ends, hit when 0.5 sin(45 deg - phi) = w + r
    w, r = 0.01, 0.05
    world = Detection([BodySpec('bar', 'box', (1.0, 2 * w, 2 * w)),
                       BodySpec('ball', 'sphere', (r,), static=True)], SETTINGS)
    ball = [0.5 * math.cos(math.pi / 4), 0.5 * math.sin(math.pi / 4), 0.0]
    quarter = rotation.from_rotation_vector(np.array([0, 0, math.pi / 2]))
    before = states([[0, 0, 0], ball])
    after = states([[0, 0, 0], ball], [quarter, [0, 0, 0, 1]])
    contacts = world.detect(before, after)
    expected = (math.pi / 4 - math.asin((w + r) / 0.5)) / (math.pi / 2)
    print(f'toi {contacts.toi[0]:.6f} expected {expected:.6f}')
    assert contacts.count >= 1 and set(contacts.kind) == {ContactKind.TUNNELLED}
    assert abs(contacts.toi[0] - expected) <= 2 * SETTINGS.toi_tolerance
    normal = np.array([-math.sin(expected * math.pi / 2), math.cos(expected * math.pi / 2), 0])
    np.testing.assert_allclose(contacts.normal[0], normal, atol=1e-3)   # the bar's side face


def test_deep_overlap_takes_the_normal_from_the_previous_closest_points() -> None:
    # a ball falls into the top face of a block near its side: halfway through the step
    # it is closer to the side face, so EPA there would push it sideways (+x)
    block = BodySpec('block', 'box', (1.0, 1.0, 0.2), static=True)
    ball = BodySpec('ball', 'sphere', (0.1,))
    before, after = states([[0, 0, 0], [0.45, 0, 0.23]]), states([[0, 0, 0], [0.45, 0, -0.17]])
    coarse = Detection([block, ball], SETTINGS.with_values(toi_max_iterations=1))
    contacts = coarse.detect(before, after)
    assert contacts.count == 1 and contacts.kind[0] == ContactKind.IMPACT
    assert contacts.toi[0] == pytest.approx(0.5)   # one halving: deep at the reported time
    np.testing.assert_allclose(contacts.normal[0], [0, 0, 1], atol=1e-9)
    fine = Detection([block, ball], SETTINGS).detect(before, after)
    print(f'toi {fine.toi[0]:.6f} expected {0.03 / 0.4:.6f}')
    assert abs(fine.toi[0] - 0.03 / 0.4) <= SETTINGS.toi_tolerance
    np.testing.assert_allclose(fine.normal[0], [0, 0, 1], atol=1e-6)


def stack(levels: int) -> tuple[list[BodySpec], BodyStates]:
    specs = [BodySpec('floor', 'box', (4, 4, 0.2), static=True)]
    positions = [[0, 0, -0.1]]
    for k in range(levels):
        specs.append(BodySpec(f'box{k}', 'box', (0.2, 0.2, 0.2)))
        positions.append([0.01 * k, 0, 0.1 + 0.2 * k - 0.001 * (k + 1)])
    return specs, states(positions)


def test_stored_manifolds_match_a_fresh_query_and_keep_their_features() -> None:
    specs, resting = stack(4)
    world = Detection(specs, SETTINGS)
    first = world.detect(resting, resting)
    assert first.count == 16 and set(first.kind) == {ContactKind.PERSISTENT}
    nudged = resting.copy()
    nudged.position[2:] += [0.3 * REUSE_LIMIT, 0, -0.0002]   # below the reuse limit
    stored = world.detect(resting, nudged)
    fresh = Detection(specs, SETTINGS).detect(resting, nudged)
    np.testing.assert_array_equal(stored.body_a, fresh.body_a)
    np.testing.assert_array_equal(stored.feature, fresh.feature)
    np.testing.assert_array_equal(stored.feature, first.feature)
    np.testing.assert_allclose(stored.separation, fresh.separation, atol=1e-9)
    np.testing.assert_allclose(stored.normal, fresh.normal, atol=1e-9)
    np.testing.assert_allclose(stored.point, fresh.point, atol=REUSE_LIMIT)
    lifted = nudged.copy()
    lifted.position[4] += [0, 0, 2 * SETTINGS.speculative_margin]   # top box leaves
    assert world.detect(nudged, lifted).count == 12


def test_stored_points_of_a_small_box_stay_within_the_reuse_limit_of_a_fresh_query() -> None:
    """A stored manifold is reused while its pair shifted less than reuse_shift times the
    thinner body's smallest half extent, so a reused point lies within that of the point a
    fresh query finds, whatever the body's size: a 1 cm cube (limit 0.1 mm) on a floor,
    moved 0.15 mm and then 0.15 mm more along it (a fixed 1 mm limit kept the first points
    through both moves: 0.15 mm from a fresh query's)."""
    size = 0.01
    specs = [BodySpec('floor', 'plane', (0.0, 0.0, 1.0, 0.0), static=True),
             BodySpec('box', 'box', (size,) * 3)]
    limit = REUSE_SHIFT * 0.5 * size
    resting = states([[0, 0, 0], [0, 0, 0.5 * size - 1e-5]])
    world = Detection(specs, SETTINGS)
    world.detect(resting, resting)
    previous = resting
    for step in (1, 2):
        moved = resting.copy()
        moved.position[1, 0] += step * 1.5 * limit
        stored = world.detect(previous, moved)
        fresh = Detection(specs, SETTINGS).detect(previous, moved)
        # (the fresh query also gives the top corners, within the margin: by feature)
        same = [list(fresh.feature).index(f) for f in stored.feature]
        assert stored.count >= 4 and set(stored.kind) == {ContactKind.PERSISTENT}
        np.testing.assert_allclose(stored.separation, fresh.separation[same], atol=1e-12)
        error = np.linalg.norm(stored.point - fresh.point[same], axis=1).max()
        print(f'move {step}: stored points {1e3 * error:.3f} mm from a fresh query\'s '
              f'(limit {1e3 * limit:.3f} mm)')
        assert error <= limit
        previous = moved


def test_stored_points_of_a_pair_moved_along_its_normal_stay_within_the_reuse_limit() -> None:
    """A shift along a manifold's normal moves no point along either face: however far a
    pair was lifted apart or pressed together (a box of a stack rocked by the push-out of
    its overlap, 0.1-0.2 mm a 30 Hz step, then back), its rows' gaps are a fresh query's
    and its points lie within the reuse limit of a fresh query's, the limit being spent
    only by the shift along the faces (here a nudge of half of it). (The lifts keep the pair,
    at rest, within its margin.)"""
    specs, resting = stack(4)
    world = Detection(specs, SETTINGS)
    first = world.detect(resting, resting)
    assert first.count == 16
    pair = (first.body_a == 1) & (first.body_b == 2)
    assert pair.sum() == 4
    for lift in (1.5 * REUSE_LIMIT, -0.5 * REUSE_LIMIT, 2 * REUSE_LIMIT):
        assert lift < RESTING
        moved = resting.copy()
        moved.position[2:] += [0.5 * REUSE_LIMIT, 0.0, lift]   # pair (1, 2) moves
        stored = world.detect(moved, moved)
        fresh = Detection(specs, SETTINGS).detect(moved, moved)
        np.testing.assert_array_equal(stored.body_a, fresh.body_a)
        np.testing.assert_array_equal(stored.feature, fresh.feature)
        np.testing.assert_array_equal(stored.feature, first.feature)
        np.testing.assert_allclose(stored.separation, fresh.separation, rtol=0, atol=1e-12)
        # parallel faces: the lift is the gap's change, the nudge along them none
        np.testing.assert_allclose(stored.separation[pair], first.separation[pair] + lift,
                                   rtol=0, atol=1e-12)
        error = np.linalg.norm(stored.point - fresh.point, axis=1).max()
        print(f'lift {1e3 * lift:+.1f} mm: stored points {1e3 * error:.3f} mm from a fresh '
              f'query\'s (limit {1e3 * REUSE_LIMIT:.1f} mm)')
        assert error <= REUSE_LIMIT


def test_motion_a_pair_shares_keeps_its_stored_points() -> None:
    """A stack that its source integrated one 30 Hz period under gravity arrives g dt^2
    (11 mm) lower, every box with its neighbours: each pair of boxes moved only by the
    nudge relative to each other, so it keeps its stored points (they move with each
    body), where a fresh query would find the corners of the upper box of the lowest pair
    moved by the whole nudge."""
    specs, resting = stack(4)
    world = Detection(specs, SETTINGS)
    first = world.detect(resting, resting)
    shift = np.array([0.0, 0.0, -9.81 / 30.0 ** 2])
    nudge = np.array([0.3 * REUSE_LIMIT, 0.0, 0.0])   # all boxes but the lowest
    fallen = resting.copy()
    fallen.position[1:] += shift
    fallen.position[2:] += nudge
    moved = world.detect(resting, fallen)
    boxes = first.body_a > 0                           # the box-on-box pairs, not the floor's
    assert boxes.sum() == 12 and (moved.body_a > 0).sum() == 12
    np.testing.assert_array_equal(moved.feature[moved.body_a > 0], first.feature[boxes])
    # the bottom box (body 1) is not nudged: its pair's midpoints move by half the nudge
    share = np.where(first.body_a[boxes] == 1, 0.5, 1.0)[:, None]
    np.testing.assert_allclose(moved.point[moved.body_a > 0],
                               first.point[boxes] + shift + share * nudge, rtol=0, atol=1e-9)


def test_a_box_falling_along_a_wall_keeps_its_stored_points() -> None:
    """A box 4 mm from a wall (within the margin of a pair at rest) that its source
    integrated one 30 Hz period under gravity moved g dt^2 (11 mm) along the wall: its
    distance to the wall did not change (only the motion along the wall's normal changes
    the gap to a half-space), so the pair, in
    contact (within the margin) at both ends and barely turned relative to its stored
    manifold, keeps its stored points: they move with each body, the wall's stays where
    it was and the midpoints move by half the nudge, where a fresh query finds the box's
    corners projected on the wall, moved by the whole nudge."""
    specs = [BodySpec('wall', 'plane', (1.0, 0.0, 0.0, 0.0), static=True),
             BodySpec('box', 'box', (0.2, 0.2, 0.2))]
    resting = states([[0, 0, 0], [0.104, 0, 1.0]])
    assert 0.004 < RESTING
    world = Detection(specs, SETTINGS)
    first = world.detect(resting, resting)
    assert first.count == 4 and set(first.kind) == {ContactKind.PERSISTENT}
    fall = np.array([0.0, 0.0, -9.81 / 30.0 ** 2])
    nudge = np.array([0.0, 0.3 * REUSE_LIMIT, 0.0])   # below the reuse limit
    above = resting.copy()
    above.position[1] -= fall
    nudged = resting.copy()
    nudged.position[1] += nudge
    moved = world.detect(above, nudged)
    fresh = Detection(specs, SETTINGS).detect(above, nudged)
    assert set(moved.kind) == set(fresh.kind) == {ContactKind.PERSISTENT}
    np.testing.assert_array_equal(moved.feature, first.feature)
    np.testing.assert_allclose(moved.separation, fresh.separation, atol=1e-12)
    np.testing.assert_allclose(moved.point, first.point + 0.5 * nudge, rtol=0, atol=1e-12)
    np.testing.assert_allclose(fresh.point, first.point + nudge, rtol=0, atol=1e-12)


def test_frozen_bodies_are_held_at_their_current_pose() -> None:
    world = Detection([BodySpec('a', 'sphere', (0.1,)), BodySpec('b', 'sphere', (0.1,))],
                      SETTINGS)
    # b jumped from far above into a: as a moving body this is an impact
    before, after = states([[0, 0, 0], [0, 0, 5.0]]), states([[0, 0, 0], [0, 0, 0.15]])
    moving = world.detect(before, after)
    assert list(moving.kind) == [ContactKind.IMPACT]
    frozen = world.detect(before, after, active=np.array([True, False]))
    assert list(frozen.kind) == [ContactKind.PERSISTENT]   # as if it had been there all along
    assert frozen.separation[0] == pytest.approx(-0.05)
    # a wall swept through a ball is caught, unless the wall is frozen
    wall = Detection([BodySpec('wall', 'box', (0.01, 1, 1)),
                      BodySpec('ball', 'sphere', (0.01,), static=True)], SETTINGS)
    crossing = wall.detect(states([[-1, 0, 0], [0, 0, 0]]), states([[1, 0, 0], [0, 0, 0]]))
    assert list(crossing.kind) == [ContactKind.TUNNELLED]
    held = wall.detect(states([[-1, 0, 0], [0, 0, 0]]), states([[1, 0, 0], [0, 0, 0]]),
                       active=np.array([False, True]))
    assert held.count == 0   # both fixed: nothing to resolve


def test_no_contacts_between_two_fixed_bodies_and_none_when_far() -> None:
    world = Detection([BodySpec('floor', 'plane', (0, 0, 1, 0), static=True),
                       BodySpec('rock', 'box', (1, 1, 1), static=True),
                       BodySpec('ball', 'sphere', (0.1,))], SETTINGS)
    state = states([[0, 0, 0], [0, 0, 0.4], [3, 0, 1.0]])
    assert world.detect(state, state).count == 0


def test_non_finite_or_zero_poses_give_no_contacts_and_no_nan() -> None:
    world = Detection([BodySpec('floor', 'plane', (0, 0, 1, 0), static=True),
                       BodySpec('good', 'sphere', (0.1,)), BodySpec('bad', 'box', (1, 1, 1))],
                      SETTINGS)
    state = states([[0, 0, 0], [0, 0, 0.09], [0, 0, 0.4]])
    for broken in ('nan', 'zero'):
        after = state.copy()
        if broken == 'nan':
            after.position[2, 0] = np.nan
        else:
            after.orientation[2] = 0.0
        contacts = world.detect(state, after)
        assert list(zip(contacts.body_a, contacts.body_b)) == [(0, 1)], broken
        for field in ('point', 'normal', 'separation', 'toi'):
            assert np.all(np.isfinite(getattr(contacts, field))), (broken, field)


def test_every_detection_setting_reaches_the_compiled_detector_by_name():
    """Detection's settings are handed to C++ field by field, by name, never by position:
    each compiled field takes the SolverSettings value of its name (distinct values, so a
    swapped pair shows), and the compiled defaults agree with SolverSettings' (no second
    truth)."""
    import dataclasses

    from collres_ros.core import _native
    from collres_ros.core.config import SOLVER_TUNING
    from collres_ros.core.detection import Detection, DETECTION_FIELDS, DETECTION_TUNING
    compiled = _native.DetectionSettings()
    names = sorted(n for n in dir(compiled) if not n.startswith('_'))
    assert names == sorted(DETECTION_FIELDS + DETECTION_TUNING)
    defaults = SolverSettings()
    for name in DETECTION_FIELDS:
        assert getattr(compiled, name) == getattr(defaults, name), name
    tuning = {spec.name: spec.default for spec in SOLVER_TUNING}
    for name in DETECTION_TUNING:
        assert getattr(compiled, name) == tuning[name], name
        assert getattr(Detection([BodySpec('a', 'sphere', (0.1,))], defaults)._native.settings,
                       name) == tuning[name], name
    changed = dataclasses.replace(
        defaults, speculative_margin=0.031, toi_tolerance=3.2e-5, toi_max_iterations=33,
        ccd=False, linear_slop=3.4e-4, restitution_threshold=0.35, max_pairs=3600,
        max_contacts=3700, max_contacts_per_pair=5)
    detection = Detection([BodySpec('a', 'sphere', (0.1,)), BodySpec('b', 'box', (1, 1, 1))],
                          changed)
    handed = detection._native.settings
    for name in DETECTION_FIELDS:
        assert getattr(handed, name) == getattr(changed, name), name
