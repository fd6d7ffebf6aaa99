"""The step budget: a step's work and memory are bounded whatever the poses.

Every body at one point is inside every validation limit, yet gives N (N - 1) / 2
deep pairs. With ``max_pairs`` and ``max_contacts`` (as MuJoCo's nconmax and PhysX's
contact buffer) a step queries only the pairs whose bounding spheres overlap deepest
and keeps the deepest rows, says what it dropped, and the resolver counts the step
(``contact_budget``, reported in /diagnostics). A scene within the budget is untouched.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from collres_ros.core.config import SolverSettings
from collres_ros.core.detection import Detection
from collres_ros.core.pipeline import Resolver
from collres_ros.core.types import BodyInput, BodySpec
from collres_ros.ros import params
from contacts import at_rest

COUNT = 60
BOXES = [BodySpec(f'b{k}', 'box', (0.1, 0.1, 0.1)) for k in range(COUNT)]


def clustered(seed: int = 4) -> np.ndarray:
    """Box centres within a few cm of one point: every pair overlaps, by differing depths."""
    return np.random.default_rng(seed).uniform(-0.04, 0.04, (COUNT, 3))


def rows(detection: Detection, positions: np.ndarray):
    state = at_rest(positions)
    return detection.detect(state, state)


def test_beyond_the_contact_budget_the_deepest_rows_are_kept_in_pair_order() -> None:
    positions = clustered()
    unbounded = rows(Detection(BOXES, SolverSettings(max_contacts=10_000_000)), positions)
    budget = 500
    assert unbounded.count > 4 * budget
    detection = Detection(BOXES, SolverSettings(max_contacts=budget))
    kept = rows(detection, positions)
    print(unbounded.count, 'rows unbounded; kept', kept.count, 'dropped', detection.budget)
    assert kept.count == budget and detection.budget == (0, unbounded.count - budget)
    deepest = np.sort(unbounded.separation)[:budget]
    assert np.array_equal(np.sort(kept.separation), deepest)
    assert kept.separation.max() <= np.sort(unbounded.separation)[budget]
    order = kept.body_a * COUNT + kept.body_b
    assert np.all(np.diff(order) >= 0), 'rows stay grouped by pair in (a, b) order'


def test_beyond_the_pair_budget_the_deepest_overlapping_pairs_are_queried() -> None:
    positions = clustered()
    budget = 200
    detection = Detection(BOXES, SolverSettings(max_pairs=budget))
    kept = rows(detection, positions)
    pairs = set(zip(kept.body_a.tolist(), kept.body_b.tolist()))
    total = COUNT * (COUNT - 1) // 2
    print(len(pairs), 'pairs with rows; dropped', detection.budget)
    assert detection.budget[0] == total - budget and 0 < len(pairs) <= budget
    # the queried pairs are the closest centres (equal spheres: the deepest overlap)
    distance = {(a, b): float(np.linalg.norm(positions[a] - positions[b]))
                for a in range(COUNT) for b in range(a + 1, COUNT)}
    cut = sorted(distance.values())[budget - 1]
    assert all(distance[pair] <= cut for pair in pairs)


def test_a_scene_within_the_budget_is_unchanged() -> None:
    rng = np.random.default_rng(9)
    positions = np.c_[rng.uniform(0, 2.0, (COUNT, 2)), rng.uniform(0, 0.3, COUNT)]
    within = rows(Detection(BOXES, SolverSettings()), positions)
    huge = rows(Detection(BOXES, SolverSettings(max_pairs=10_000_000,
                                                max_contacts=10_000_000)), positions)
    assert within.count > 0
    for field in ('body_a', 'body_b', 'point', 'normal', 'separation', 'feature'):
        assert np.array_equal(getattr(within, field), getattr(huge, field))


def test_the_resolver_counts_steps_over_the_budget_and_serves_every_body() -> None:
    names = [spec.name for spec in BOXES]
    values = {'bodies': names, **{f'body.{n}.shape': 'box' for n in names},
              **{f'body.{n}.size': [0.1, 0.1, 0.1] for n in names},
              'solver.max_pairs': 100, 'solver.max_contacts': 300}
    resolver = Resolver.for_scene(params.scene_from_values(values))
    inputs = [BodyInput(n, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0, 1.0), (0.0, 0.0, 0.0),
                        (0.0, 0.0, 0.0), 'world', 'world') for n in names]
    step = resolver.resolve(10**12, inputs)
    print(step.budget, step.report.contacts.count, dict(resolver.totals))
    assert step.budget[0] == COUNT * (COUNT - 1) // 2 - 100 and step.budget[1] > 0
    assert step.report.contacts.count == 300 and len(step.names) == COUNT
    assert np.isfinite(step.states.position).all()
    assert resolver.totals['contact_budget'] == 1
    apart = [replace(i, position=(float(k), 0.0, 0.0)) for k, i in enumerate(inputs)]
    calm = resolver.resolve(10**12 + 10**10, apart)   # after max_dt: a fresh start, apart
    assert calm.budget == (0, 0) and resolver.totals['contact_budget'] == 1
