"""Detection: broad-phase backends, rotational sweeps, the closest-points normal, stored manifolds,
frozen bodies. (Translational time of impact, tunnelling and manifolds: test_collision_laws.)"""

from __future__ import annotations

import math

import numpy as np
import pytest

from collres_ros.core import rotation
from collres_ros.core.broadphase import FatPairs, TreeBroadPhase, overlapping_pairs
from collres_ros.core.collision import REUSE_TRANSLATION, CollisionWorld
from collres_ros.core.config import SolverSettings
from collres_ros.core.types import BodySpec, BodyStates, ContactKind
from contacts import at_rest

SETTINGS = SolverSettings()
states = at_rest


def brute_pairs(lo: np.ndarray, hi: np.ndarray) -> set[tuple[int, int]]:
    """All pairs i < j of overlapping boxes, by testing every pair."""
    touch = np.all((lo[:, None, :] <= hi[None, :, :]) & (lo[None, :, :] <= hi[:, None, :]),
                   axis=2)
    i, j = np.nonzero(np.triu(touch, k=1))
    return set(zip(i.tolist(), j.tolist()))


def test_broad_phase_backends_agree_with_all_pairs_over_moving_boxes() -> None:
    rng = np.random.default_rng(3)
    count = 200
    centre = rng.uniform(0.0, 1.0, (count, 3))
    half = rng.uniform(0.02, 0.08, (count, 3))
    fat, tree = FatPairs(skin=0.04), TreeBroadPhase(count)
    for step in range(6):   # some bodies leave their fat boxes, some do not
        centre += rng.normal(0.0, 0.01 if step % 2 else 0.05, (count, 3))
        lo, hi = centre - half, centre + half
        expected = brute_pairs(lo, hi)
        for name, pairs in (('sweep', overlapping_pairs(lo, hi)), ('fat', fat.pairs(lo, hi)),
                            ('tree', tree.pairs(lo, hi))):
            found = list(zip(*(p.tolist() for p in pairs)))
            assert len(found) == len(set(found)), name
            assert set(found) == expected, (name, step)
    print(f'{len(expected)} overlapping pairs of {count} boxes')
    assert len(expected) > 100


def test_world_gives_the_same_contacts_with_either_broad_phase() -> None:
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
    results = [CollisionWorld(specs, SETTINGS, broad_phase=name).detect(before, after)
               for name in ('sweep', 'tree')]
    assert results[0].count > 20
    for field in ('body_a', 'body_b', 'kind', 'feature'):
        np.testing.assert_array_equal(getattr(results[0], field), getattr(results[1], field))
    np.testing.assert_allclose(results[0].separation, results[1].separation, atol=1e-12)


def test_spinning_bar_sweeping_through_a_sphere_is_caught_at_the_analytic_angle() -> None:
    # a 1 m bar (half width w) turns 90 deg about z in one step; a ball of radius r sits at
    # 45 deg, 0.5 m out: apart at both ends, hit when 0.5 sin(45 deg - phi) = w + r
    w, r = 0.01, 0.05
    world = CollisionWorld([BodySpec('bar', 'box', (1.0, 2 * w, 2 * w)),
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
    coarse = CollisionWorld([block, ball], SETTINGS.with_values(toi_max_iterations=1))
    contacts = coarse.detect(before, after)
    assert contacts.count == 1 and contacts.kind[0] == ContactKind.IMPACT
    assert contacts.toi[0] == pytest.approx(0.5)   # one halving: deep at the reported time
    np.testing.assert_allclose(contacts.normal[0], [0, 0, 1], atol=1e-9)
    fine = CollisionWorld([block, ball], SETTINGS).detect(before, after)
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
    world = CollisionWorld(specs, SETTINGS)
    first = world.detect(resting, resting)
    assert first.count == 16 and set(first.kind) == {ContactKind.PERSISTENT}
    nudged = resting.copy()
    nudged.position[2:] += [0.3 * REUSE_TRANSLATION, 0, -0.0002]   # below the reuse limit
    stored = world.detect(resting, nudged)
    fresh = CollisionWorld(specs, SETTINGS).detect(resting, nudged)
    np.testing.assert_array_equal(stored.body_a, fresh.body_a)
    np.testing.assert_array_equal(stored.feature, fresh.feature)
    np.testing.assert_array_equal(stored.feature, first.feature)
    np.testing.assert_allclose(stored.separation, fresh.separation, atol=1e-9)
    np.testing.assert_allclose(stored.normal, fresh.normal, atol=1e-9)
    np.testing.assert_allclose(stored.point, fresh.point, atol=REUSE_TRANSLATION)
    lifted = nudged.copy()
    lifted.position[4] += [0, 0, 2 * SETTINGS.speculative_margin]   # top box leaves
    assert world.detect(nudged, lifted).count == 12


def test_frozen_bodies_are_held_at_their_current_pose() -> None:
    world = CollisionWorld([BodySpec('a', 'sphere', (0.1,)), BodySpec('b', 'sphere', (0.1,))],
                           SETTINGS)
    # b jumped from far above into a: as a moving body this is an impact
    before, after = states([[0, 0, 0], [0, 0, 5.0]]), states([[0, 0, 0], [0, 0, 0.15]])
    moving = world.detect(before, after)
    assert list(moving.kind) == [ContactKind.IMPACT]
    frozen = world.detect(before, after, active=np.array([True, False]))
    assert list(frozen.kind) == [ContactKind.PERSISTENT]   # as if it had been there all along
    assert frozen.separation[0] == pytest.approx(-0.05)
    # a wall swept through a ball is caught, unless the wall is frozen
    wall = CollisionWorld([BodySpec('wall', 'box', (0.01, 1, 1)),
                           BodySpec('ball', 'sphere', (0.01,), static=True)], SETTINGS)
    crossing = wall.detect(states([[-1, 0, 0], [0, 0, 0]]), states([[1, 0, 0], [0, 0, 0]]))
    assert list(crossing.kind) == [ContactKind.TUNNELLED]
    held = wall.detect(states([[-1, 0, 0], [0, 0, 0]]), states([[1, 0, 0], [0, 0, 0]]),
                       active=np.array([False, True]))
    assert held.count == 0   # both fixed: nothing to resolve


def test_no_contacts_between_two_fixed_bodies_and_none_when_far() -> None:
    world = CollisionWorld([BodySpec('floor', 'plane', (0, 0, 1, 0), static=True),
                            BodySpec('rock', 'box', (1, 1, 1), static=True),
                            BodySpec('ball', 'sphere', (0.1,))], SETTINGS)
    state = states([[0, 0, 0], [0, 0, 0.4], [3, 0, 1.0]])
    assert world.detect(state, state).count == 0


def test_non_finite_or_zero_poses_give_no_contacts_and_no_nan() -> None:
    world = CollisionWorld([BodySpec('floor', 'plane', (0, 0, 1, 0), static=True),
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
