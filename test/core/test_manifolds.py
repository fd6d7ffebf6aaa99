"""Manifolds as the solver's constraints: detection hands them over as spans of rows.

Detection gives each manifold (the 1-4 points of one body pair found together) as a span
``(body_a, body_b, first, count)`` of its rows (``ContactSet.manifolds``); the spans tile
the rows in order, and the step budget keeps each manifold's kept rows. The solver takes
each span as one constraint (its normal rows solved as one block) and never regroups
rows by pair, so one pair may have several manifolds (pieces of compound bodies), each
its own block.
"""

from __future__ import annotations

import numpy as np
import pytest

from collres_ros.core.config import SolverSettings
from collres_ros.core.detection import Detection
from collres_ros.core.types import BodySpec, ContactKind, ContactSet
from collres_ros.core.world import World

from contacts import at_rest, contact_set, FixedContacts, sphere, states  # noqa: I100


def assert_tiles(contacts: ContactSet) -> None:
    """The manifolds tile the rows in order, each of one pair, 1 to 4 points."""
    spans = contacts.manifolds
    assert spans.dtype == np.int64 and spans.shape[1] == 4
    assert np.array_equal(spans[:, 2], np.cumsum(spans[:, 3]) - spans[:, 3])
    assert spans[:, 3].sum() == contacts.count
    assert spans[:, 3].min() >= 1 and spans[:, 3].max() <= 4
    owner = np.repeat(np.arange(len(spans)), spans[:, 3])
    assert np.array_equal(contacts.body_a, spans[owner, 0])
    assert np.array_equal(contacts.body_b, spans[owner, 1])


def test_detection_gives_one_manifold_per_pair_as_spans_that_tile_the_rows() -> None:
    """A pile of boxes and spheres on a floor: the manifolds tile the rows in (a, b)
    order, a pair's patch first (then its speculative corners, each body's a manifold of
    its own), and within the step budget the deepest rows keep their manifolds (each
    manifold its kept rows)."""
    rng = np.random.default_rng(3)
    bodies = [BodySpec('floor', 'box', (4.0, 4.0, 0.2), static=True)]
    bodies += [BodySpec(f'b{k}', 'box', (0.2, 0.2, 0.2)) if k % 2 else
               BodySpec(f's{k}', 'sphere', (0.1,)) for k in range(40)]
    positions = np.vstack([[0.0, 0.0, -0.1],
                           rng.uniform([-0.5, -0.5, 0.08], [0.5, 0.5, 0.6], (40, 3))])
    state = at_rest(positions)
    contacts = Detection(bodies, SolverSettings()).detect(state, state)
    assert contacts.count > 100
    assert_tiles(contacts)
    pairs = contacts.manifolds[:, 0] * len(bodies) + contacts.manifolds[:, 1]
    assert np.all(np.diff(pairs) >= 0), 'manifolds in (a, b) order'
    budget = contacts.count // 3
    limited = Detection(bodies, SolverSettings(max_contacts=budget)).detect(state, state)
    assert limited.count == budget
    assert_tiles(limited)
    kept_pairs = limited.manifolds[:, 0] * len(bodies) + limited.manifolds[:, 1]
    assert set(kept_pairs.tolist()) <= set(pairs.tolist())


def two_rows_at_one_point(spans) -> tuple[World, object]:
    """A ball (1 kg, e = 0) falling at 2 m/s onto a fixed ball, two contact rows at the
    same point (normal +z), grouped into manifolds by ``spans``."""
    bodies = [sphere('ground', 0.1, 1.0, e=0.0, static=True), sphere('ball', 0.1, 1.0, e=0.0)]
    rows = contact_set([0, 0], [1, 1], [[0.0, 0.0, 0.1]] * 2, [0.0, 0.0, 1.0], -0.001,
                       toi=0.5, kind=ContactKind.IMPACT)
    rows.manifolds = np.array(spans, np.int64)
    world = World(bodies, SolverSettings(), FixedContacts(rows))
    return world, rows


def test_two_manifolds_of_one_pair_are_solved_as_two_blocks() -> None:
    """The same two coincident rows of one pair: as one manifold they are one block,
    whose least-norm answer shares the impact equally; as two manifolds they are two
    constraints solved one after the other, and the first stops the ball alone (the
    second finds no approach left). The ball stops either way (e = 0)."""
    before = states([[0.0, 0.0, 0.3], [0.0, 0.0, 0.2]], [[0.0] * 3, [0.0, 0.0, -2.0]])
    after = states([[0.0, 0.0, 0.3], [0.0, 0.0, 0.199]], [[0.0] * 3, [0.0, 0.0, -2.0]])
    answers = {}
    for name, spans in (('one', [[0, 1, 0, 2]]), ('two', [[0, 1, 0, 1], [0, 1, 1, 1]])):
        world, _ = two_rows_at_one_point(spans)
        result = world.step(before, after, 1.0 / 240.0)
        answers[name] = result
        print(name, 'manifold(s): impulses', result.report.normal_impulse,
              'ball v', result.states.linear[1])
    one, two = answers['one'], answers['two']
    assert one.report.normal_impulse == pytest.approx([1.0, 1.0], rel=1e-6)
    assert two.report.normal_impulse == pytest.approx([2.0, 0.0], rel=1e-6, abs=1e-9)
    for result in (one, two):
        assert abs(result.states.linear[1, 2]) < 1e-9 + 0.5 * 9.81 / 240.0


def test_manifolds_that_do_not_tile_the_rows_are_refused() -> None:
    """The compiled step checks the spans: each of one pair, tiling the rows in order."""
    before = states([[0.0, 0.0, 0.3], [0.0, 0.0, 0.2]], [[0.0] * 3, [0.0, 0.0, -2.0]])
    for spans in ([[0, 1, 0, 1]], [[0, 1, 1, 1], [0, 1, 0, 1]], [[0, 2, 0, 2]],
                  [[0, 1, 0, 3]]):
        world, _ = two_rows_at_one_point(spans)
        with pytest.raises(ValueError, match='manifolds'):
            world.step(before, before, 1.0 / 240.0)
