"""Collision filtering: group and mask bits and ignored pairs, applied in the broad phase.

Each scene holds a filtered pair and an identical unfiltered one beside it, so every test
checks that the event under test happens where it is allowed (contacts, changed
velocities) and not where it is filtered (no contact, the input state kept bit for bit).
"""

from __future__ import annotations

import numpy as np
import pytest

from collres_ros.core import _native
from collres_ros.core.config import ALL_COLLISION_BITS, SolverSettings
from collres_ros.core.detection import Detection
from collres_ros.core.types import BodySpec, BodyStates, CollisionFilter
from collres_ros.core.world import World

DT = 1 / 240
GRAVITY = np.array([0.0, 0.0, -9.81])
OWN_GROUP = 2                                   # robot links: collide with the world ...
NOT_OWN = ALL_COLLISION_BITS & ~OWN_GROUP       # ... but not with one another
# 0 floor (half-space z <= 0), 1-2 the filtered pair, 3-4 the same pair unfiltered,
# 5 a ball sunk into the floor (filtered by bits in one test), 6 the same ball unfiltered
SPECS = [BodySpec('floor', 'plane', (0.0, 0.0, 1.0, 0.0), static=True),
         BodySpec('a', 'box', (0.2, 0.2, 0.2), restitution=0.0),
         BodySpec('b', 'box', (0.2, 0.2, 0.2), restitution=0.0),
         BodySpec('c', 'box', (0.2, 0.2, 0.2), restitution=0.0),
         BodySpec('d', 'box', (0.2, 0.2, 0.2), restitution=0.0),
         BodySpec('sunk', 'sphere', (0.1,)),
         BodySpec('ball', 'sphere', (0.1,))]
A, B, C, D, SUNK, BALL = 1, 2, 3, 4, 5, 6


def scene_states() -> tuple[BodyStates, BodyStates]:
    """Previous and current states: a-b and c-d overlap by 5 cm and close at 2 m/s each,
    in the air; sunk and ball are 5 cm into the floor and falling at 1 m/s."""
    previous = BodyStates.zeros(len(SPECS))
    previous.position[1:] = [[0.0, 0.0, 1.0], [0.15, 0.0, 1.0], [0.0, 2.0, 1.0],
                             [0.15, 2.0, 1.0], [1.0, 0.0, 0.05], [1.0, 2.0, 0.05]]
    previous.linear[1:] = [[1.0, 0.0, 0.0], [-1.0, 0.0, 0.0], [1.0, 0.0, 0.0],
                           [-1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 0.0, -1.0]]
    current = previous.copy()
    current.linear[1:] += GRAVITY * DT
    current.position[1:] += current.linear[1:] * DT
    return previous, current


def pairs_of(report) -> set[tuple[int, int]]:
    c = report.contacts
    return set(zip(c.body_a.tolist(), c.body_b.tolist()))


def step(collision_filter: CollisionFilter | None):
    previous, current = scene_states()
    world = World(SPECS, SolverSettings(), collision_filter=collision_filter)
    return current, world.step(previous, current, DT)


def assert_filtered(filtered: list[int], current: BodyStates, result) -> None:
    """The filtered bodies keep their input state exactly; their twins were resolved."""
    pairs = pairs_of(result.report)
    print('contact pairs:', sorted(pairs))
    assert (C, D) in pairs and (0, BALL) in pairs          # the twins collided ...
    for twin in (C, D, BALL):                              # ... and were pushed
        assert not np.allclose(result.states.linear[twin], current.linear[twin], atol=1e-3)
    assert result.states.linear[C][0] < 0.5 and result.states.linear[D][0] > -0.5
    assert result.states.linear[BALL][2] > -0.1
    _, unfiltered = step(None)
    others = [k for k in range(len(SPECS)) if k not in filtered]
    for name in ('position', 'orientation', 'linear', 'angular'):   # as if nothing filtered
        np.testing.assert_allclose(getattr(result.states, name)[others],
                                   getattr(unfiltered.states, name)[others], rtol=0, atol=1e-12)
    for body in filtered:
        assert not any(body in pair for pair in pairs)
        for name in ('position', 'orientation', 'linear', 'angular'):
            np.testing.assert_array_equal(getattr(result.states, name)[body],
                                          getattr(current, name)[body])
        print(f'{SPECS[body].name}: velocity kept {result.states.linear[body]}')


def test_bits_filter_a_pair_and_a_half_space_pair_and_nothing_else() -> None:
    bits = CollisionFilter.default(len(SPECS)).with_body(A, OWN_GROUP, NOT_OWN) \
        .with_body(B, OWN_GROUP, NOT_OWN).with_body(SUNK, mask=ALL_COLLISION_BITS & ~1)
    assert not bits.collides(A, B) and not bits.collides(0, SUNK)
    assert bits.collides(0, A) and bits.collides(A, C) and bits.collides(0, BALL)
    current, result = step(bits)
    assert (A, B) not in pairs_of(result.report) and (0, SUNK) not in pairs_of(result.report)
    assert_filtered([A, B, SUNK], current, result)


def test_ignored_pairs_give_no_contact_and_keep_their_velocities() -> None:
    ignored = CollisionFilter.default(len(SPECS)).ignoring((B, A), (SUNK, 0))
    assert ignored.ignored == ((0, SUNK), (A, B))
    current, result = step(ignored)
    assert_filtered([A, B, SUNK], current, result)


def test_default_filter_changes_nothing() -> None:
    previous, current = scene_states()
    plain = World(SPECS, SolverSettings()).step(previous, current, DT)
    explicit = World(SPECS, SolverSettings(), collision_filter=CollisionFilter.default(
        len(SPECS))).step(previous, current, DT)
    assert {(A, B), (C, D), (0, SUNK), (0, BALL)} <= pairs_of(plain.report)
    for name in ('position', 'orientation', 'linear', 'angular'):
        np.testing.assert_array_equal(getattr(plain.states, name),
                                      getattr(explicit.states, name))


def test_filtered_pairs_never_reach_the_narrow_phase_half_spaces_included() -> None:
    previous, current = scene_states()
    detection = Detection(SPECS, SolverSettings())
    every = set(detection.candidate_pairs(previous, current))
    detection.collision_filter = CollisionFilter.default(len(SPECS)).ignoring((A, B)) \
        .with_body(SUNK, group=0)
    kept = set(detection.candidate_pairs(previous, current))
    print('broad phase:', sorted(every), '->', sorted(kept))
    assert every - kept == {(A, B), (0, SUNK)}


def test_a_runtime_change_drops_a_resting_pair_at_once_and_brings_it_back_fresh() -> None:
    """A box resting on a box (flat faces: stored manifolds and warm start in use) is
    filtered at runtime: the next step has no contact (nothing resurrected from the store
    or the cache), the top box falls freely; unfiltered, the pair is detected again."""
    specs = [BodySpec('floor', 'plane', (0.0, 0.0, 1.0, 0.0), static=True),
             BodySpec('low', 'box', (0.2, 0.2, 0.2), restitution=0.0),
             BodySpec('top', 'box', (0.2, 0.2, 0.2), restitution=0.0)]
    world = World(specs, SolverSettings())
    state = BodyStates.zeros(3)
    state.position[1:] = [[0.0, 0.0, 0.1], [0.0, 0.0, 0.3]]
    settled = None
    for _ in range(20):   # a settled stack: both pairs every step
        current = state.copy()
        current.linear[1:] += GRAVITY * DT
        current.position[1:] += current.linear[1:] * DT
        settled = world.step(state, current, DT)
        state = settled.states
    assert pairs_of(settled.report) == {(0, 1), (1, 2)}
    assert np.abs(state.linear[1:]).max() < 1e-3
    c = settled.report.contacts
    rows = (c.body_a == 1) & (c.body_b == 2)
    stacked = (c.body_a[rows], c.body_b[rows], c.feature[rows],
               np.ascontiguousarray(c.point[rows]))
    assert world._cache.lookup(*stacked)[2].all()   # warm-start impulses of the pair stored
    world.collision_filter = CollisionFilter.default(3).ignoring((1, 2))
    current = state.copy()
    current.linear[1:] += GRAVITY * DT
    current.position[1:] += current.linear[1:] * DT
    free = world.step(state, current, DT)
    print('filtered step:', sorted(pairs_of(free.report)), 'top vz', free.states.linear[2, 2])
    assert pairs_of(free.report) == {(0, 1)}
    np.testing.assert_array_equal(free.states.linear[2], current.linear[2])   # free fall
    assert not world._cache.lookup(*stacked)[2].any()   # none left to warm start it with
    assert free.states.linear[2, 2] == pytest.approx(-9.81 * DT)
    world.collision_filter = CollisionFilter.default(3)
    state = free.states
    current = state.copy()
    current.linear[1:] += GRAVITY * DT
    current.position[1:] += current.linear[1:] * DT
    again = world.step(state, current, DT)
    assert pairs_of(again.report) == {(0, 1), (1, 2)}


def test_filter_rules_and_refusals() -> None:
    f = CollisionFilter((1, 2, 3), (2, 1, 0))
    assert f.collides(0, 1) and f.collides(1, 0)       # 1 & 1 and 2 & 2
    assert not f.collides(0, 2) and not f.collides(1, 2)   # body 2 accepts nothing
    assert CollisionFilter((0, 1), (0xFFFF, 0xFFFF)).collides(0, 1) is False   # group 0
    for bad in (lambda: CollisionFilter((1,), (1, 1)),
                lambda: CollisionFilter((1 << 16,), (1,)),
                lambda: CollisionFilter((-1,), (1,)),
                lambda: CollisionFilter((True,), (1,)),
                lambda: CollisionFilter((1, 1), (1, 1), ((0, 0),)),
                lambda: CollisionFilter((1, 1), (1, 1), ((0, 2),))):
        with pytest.raises(ValueError, match='^collision filter: '):
            bad()
    detection = Detection(SPECS[:2], SolverSettings())
    with pytest.raises(ValueError, match='3 bodies, the detector has 2'):
        detection.collision_filter = CollisionFilter.default(3)
    # the compiled side refuses too
    native = _native.Detector([0, 0], [[0.1], [0.1]], [[], []], [0.1, 0.1], [False, False])
    with pytest.raises(ValueError, match='not two distinct bodies'):
        native.set_filter([1, 1], [1, 1], [(0, 5)])
    with pytest.raises(ValueError, match='one group and one mask per body'):
        native.set_filter([1], [1, 1], [])
