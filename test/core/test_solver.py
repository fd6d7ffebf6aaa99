"""Unit tests of the solver pieces: combine rules, warm-start cache, guards."""

from __future__ import annotations

import numpy as np
import pytest

from collres_ros.core import _native
from collres_ros.core.config import FRICTION_RULES, RESTITUTION_RULES, SolverSettings
from collres_ros.core.types import ContactKind, ContactState
from collres_ros.core.world import combine, World

from contacts import box, contact_set, FixedContacts, sphere, states  # noqa: I100


def test_combine_rules():
    ea, eb = np.array([0.2, 0.9]), np.array([0.8, 0.1])
    assert np.allclose(combine(ea, eb, 'average'), [0.5, 0.5])
    assert np.allclose(combine(ea, eb, 'min'), [0.2, 0.1])
    assert np.allclose(combine(ea, eb, 'max'), [0.8, 0.9])
    assert np.allclose(combine(ea, eb, 'multiply'), [0.16, 0.09])
    assert np.allclose(combine(ea, eb, 'per_object'), [0.5, 0.5])   # reported mean only
    assert np.allclose(combine(np.array([0.5]), np.array([0.5]), 'geometric'), 0.5)
    assert np.allclose(combine(np.array([0.1]), np.array([0.9]), 'geometric'), 0.3)
    with pytest.raises(KeyError):
        combine(ea, eb, 'bogus')
    assert set(RESTITUTION_RULES) | set(FRICTION_RULES) <= set(_native.CombineRule.__members__)


def test_cache_exact_nearest_and_forget():
    cache = _native.ContactCache()
    cache.store(np.array([0, 0, 1]), np.array([2, 2, 3]), np.array([7, 8, 1]),
                np.array([1.0, 2.0, 3.0]), np.eye(3),
                np.array([[0, 0, 0], [0.1, 0, 0], [1, 1, 1.0]]))
    normal, friction, found = cache.lookup(np.array([0, 0, 1, 4]), np.array([2, 2, 3, 5]),
                                           np.array([8, 99, 1, 0]),
                                           np.array([[9, 9, 9], [0.005, 0, 0], [0, 0, 0],
                                                     [0, 0, 0.0]]))
    assert normal.tolist() == [2.0, 1.0, 3.0, 0.0]      # exact, nearest point, exact, absent
    assert found.tolist() == [True, True, True, False]
    assert np.allclose(friction[1], [1, 0, 0])
    cache.forget(np.array([3]))
    assert len(cache) == 2
    assert cache.lookup(np.array([1]), np.array([3]), np.array([1]),
                        np.zeros((1, 3)))[0][0] == 0.0
    with pytest.raises(TypeError):                       # never a silent copy
        cache.lookup(np.array([1], np.int32), np.array([3]), np.array([1]), np.zeros((1, 3)))


@pytest.mark.parametrize('pairs_in_order', [True, False])
@pytest.mark.parametrize('bodies', [6, 60])
def test_cache_keeps_the_last_impulse_of_each_key_whatever_the_order(pairs_in_order, bodies):
    """Stored contacts are found by (a, b, feature), a later duplicate of a key winning,
    whether the pairs come in order (as detection lists them), each with few contacts
    (60 bodies) or many (6), or not."""
    rng = np.random.default_rng(7)
    m = 400
    a = rng.integers(0, bodies, m)
    b = a + 1 + rng.integers(0, 6, m)
    feature = rng.integers(-3, 4, m)      # few features: many duplicates within a pair
    if pairs_in_order:
        by_pair = np.lexsort((b, a))
        a, b, feature = a[by_pair], b[by_pair], feature[by_pair]
    normal = np.arange(m, dtype=float)
    cache = _native.ContactCache()
    cache.store(a, b, feature, normal, np.zeros((m, 3)), np.zeros((m, 3)))
    last = {(i, j, f): n for i, j, f, n in zip(a.tolist(), b.tolist(), feature.tolist(), normal)}
    assert len(cache) == len(last)
    absent = [(i, j, 10) for i, j, _ in last] + [(100, 101, 0)]
    queries = np.array(list(last) + absent)
    queries = queries[np.lexsort((queries[:, 1], queries[:, 0])) if pairs_in_order
                      else rng.permutation(len(queries))]
    found_normal, _, found = cache.lookup(queries[:, 0].copy(), queries[:, 1].copy(),
                                          queries[:, 2].copy(), np.zeros((len(queries), 3)))
    assert found.tolist() == [tuple(q) in last for q in queries.tolist()]
    assert found_normal.tolist() == [last.get(tuple(q), 0.0) for q in queries.tolist()]


def test_degenerate_tangent_never_nan_and_no_friction_at_rest():
    """Normal parallel to the relative velocity (head-on, friction 1): no tangential impulse."""
    bodies = [sphere('a', 0.1, 1.0, e=0.5, mu_s=1.0, mu_k=1.0),
              sphere('b', 0.1, 1.0, e=0.5, mu_s=1.0, mu_k=1.0)]
    contacts = contact_set(0, 1, [0, 0, 0], [0, 0, 1], -0.001, kind=ContactKind.PERSISTENT)
    world = World(bodies, SolverSettings(), FixedContacts(contacts))
    before = states([[0, 0, -0.1], [0, 0, 0.1]], [[0, 0, 1.0], [0, 0, -1.0]])
    result = world.step(before, before.copy(), 0.01)
    assert result.report.normal_impulse[0] > 0.0
    assert np.all(np.isfinite(result.states.linear))
    assert np.allclose(result.report.friction_impulse, 0.0)
    assert np.allclose(result.states.linear[:, :2], 0.0)


def test_non_finite_contacts_are_dropped_and_output_stays_finite():
    bodies = [sphere('a', 0.1, 1.0), sphere('b', 0.1, 1.0)]
    contacts = contact_set(0, 1, [[0, 0, 0], [np.nan, 0, 0]], [[1, 0, 0], [1, 0, 0]],
                           [-0.001, -0.001], kind=ContactKind.PERSISTENT)
    world = World(bodies, SolverSettings(), FixedContacts(contacts))
    before = states([[-0.1, 0, 0], [0.1, 0, 0]], [[1.0, 0, 0], [-1.0, 0, 0]])
    result = world.step(before, before.copy(), 0.01)
    assert result.report.contacts.count == 1
    assert all(np.all(np.isfinite(a)) for a in (result.states.position, result.states.linear))


def test_usual_contacts_unit_normals_bit_for_bit_and_none_on_any_bad_number():
    # the compiled check of detection's usual contacts divides each normal by its length
    # sqrt((x^2 + y^2) + z^2), bit for bit numpy's, and answers None (the row-by-row check)
    # on any non-finite number, a normal of length 0.5 or less, or an array not C-contiguous
    # float64 of its shape
    rng = np.random.default_rng(7)
    m = 50
    point = rng.normal(size=(m, 3))
    normal = rng.normal(size=(m, 3))
    normal *= rng.uniform(0.6, 3.0, size=(m, 1)) / np.linalg.norm(normal, axis=1)[:, None]
    separation, toi = rng.normal(size=m), rng.uniform(size=m)
    square = normal * normal
    length = np.sqrt((square[:, 0] + square[:, 1]) + square[:, 2])
    unit = _native.usual_contacts(point, normal, separation, toi)
    assert unit.tobytes() == (normal / length[:, None]).tobytes()
    assert _native.usual_contacts(point[:0], normal[:0], separation[:0], toi[:0]).shape == (0, 3)
    for name, bad in (('point', np.nan), ('normal', np.inf), ('separation', -np.inf),
                      ('toi', np.nan), ('normal', 0.0)):
        arrays = {'point': point.copy(), 'normal': normal.copy(),
                  'separation': separation.copy(), 'toi': toi.copy()}
        arrays[name][17] = bad
        assert _native.usual_contacts(**arrays) is None, name
    short = normal.copy()
    short[3] = [0.5, 0.0, 0.0]
    assert _native.usual_contacts(point, short, separation, toi) is None
    wide = np.zeros((m, 6))
    wide[:, ::2] = normal
    assert _native.usual_contacts(point, wide[:, ::2], separation, toi) is None
    assert _native.usual_contacts(point, normal.astype(np.float32), separation, toi) is None
    assert _native.usual_contacts(point, normal, separation[:-1], toi) is None


def test_contacts_with_a_strided_normal_are_checked_row_by_row_to_the_same_answer():
    # a hand-made set whose normals are a strided view takes the row-by-row check: the
    # same contacts and bits as the compiled one
    bodies = [sphere('a', 0.1, 1.0, e=0.5), sphere('b', 0.1, 1.0, e=0.5)]
    normals = np.array([[1.0, 0.1, 0.0], [0.9, -0.2, 0.1]])
    answers = []
    for strided in (False, True):
        contacts = contact_set(0, 1, [[0, 0, 0], [0, 0.01, 0]], normals, [-0.001, -0.002],
                               kind=ContactKind.PERSISTENT)
        if strided:
            wide = np.zeros((2, 6))
            wide[:, ::2] = contacts.normal
            contacts.normal = wide[:, ::2]
        world = World(bodies, SolverSettings(), FixedContacts(contacts))
        before = states([[-0.1, 0, 0], [0.1, 0, 0]], [[1.0, 0, 0], [-1.0, 0, 0]])
        result = world.step(before, before.copy(), 0.01)
        answers.append((result.states.linear.tobytes(), result.report.normal_impulse.tobytes(),
                        result.report.contacts.normal.tobytes()))
    assert answers[0] == answers[1]
    assert np.linalg.norm(np.frombuffer(answers[0][2]).reshape(-1, 3), axis=1) == \
        pytest.approx(1.0)


def test_inactive_body_with_nan_twist_is_held_and_others_resolved():
    bodies = [sphere('a', 0.1, 1.0, e=0.0), sphere('b', 0.1, 1.0, e=0.0)]
    contacts = contact_set(0, 1, [0, 0, 0], [1, 0, 0], -0.001, kind=ContactKind.PERSISTENT)
    world = World(bodies, SolverSettings(), FixedContacts(contacts))
    before = states([[-0.1, 0, 0], [0.1, 0, 0]], [[1.0, 0, 0], [np.nan, 0, 0]])
    result = world.step(before, before.copy(), 0.01, active=np.array([True, False]))
    assert np.all(np.isfinite(result.states.linear[0]))
    assert result.states.linear[0, 0] == pytest.approx(0.0, abs=1e-12)   # stopped by a wall


def test_settings_and_materials_take_effect_next_step():
    bodies = [sphere('a', 0.1, 1.0, e=1.0), sphere('b', 0.1, 1.0, e=1.0)]
    contacts = contact_set(0, 1, [0, 0, 0], [1, 0, 0], -0.01, toi=0.5)
    world = World(bodies, SolverSettings(), FixedContacts(contacts))
    before = states([[-0.11, 0, 0], [0.11, 0, 0]], [[1.0, 0, 0], [-1.0, 0, 0]])
    after = before.copy()
    after.position += after.linear * 0.02
    assert world.step(before, after, 0.02).states.linear[0, 0] == pytest.approx(-1.0)
    world.set_material(0, restitution=0.0)
    world.set_material(1, restitution=0.0)
    assert world.step(before, after, 0.02).states.linear[0, 0] == pytest.approx(0.0, abs=1e-12)
    world.settings = SolverSettings(restitution_threshold=5.0)
    world.set_material(0, restitution=1.0)
    world.set_material(1, restitution=1.0)
    loaded = after.copy()    # falling together across their line: a load, the threshold's
    loaded.linear[:, 2] -= 9.81 * 0.02
    result = world.step(before, loaded, 0.02)     # 2 m/s approach is below the threshold
    assert result.report.state[0] == ContactState.RESTING
    assert result.states.linear[0, 0] == pytest.approx(0.0, abs=1e-12)


def test_warm_start_reuses_impulses_and_forget_drops_them():
    floor = box('floor', (2.0, 2.0, 0.2), 1.0, static=True)
    cube = box('cube', (0.2, 0.2, 0.2), 1.0, mu_s=0.5, mu_k=0.5)
    corners = [[x, y, 0.0] for x in (-0.1, 0.1) for y in (-0.1, 0.1)]
    # (240 Hz: one substep, whose sweeps show the warm start alone)
    # at rest on the floor before the step; gravity moved it g dt^2 into the floor since
    contacts = contact_set(0, 1, corners, [0, 0, 1], -9.81 / 240 ** 2,
                           kind=ContactKind.PERSISTENT)
    world = World([floor, cube], SolverSettings(velocity_iterations=4),
                  FixedContacts(contacts))
    rest = states([[0, 0, -0.1], [0, 0, 0.1]], np.zeros((2, 3)))
    fall = rest.copy()
    fall.linear[1, 2] = -9.81 / 240
    fall.position[1, 2] += fall.linear[1, 2] / 240
    first = world.step(rest, fall, 1 / 240).report.normal_impulse.sum()
    cold_sweeps = world.timing['iterations']
    second = world.step(rest, fall, 1 / 240)
    warm_sweeps = world.timing['iterations']
    print('support impulse, step 1 and 2:', first, second.report.normal_impulse.sum(),
          'sweeps', cold_sweeps, warm_sweeps)
    # the second step starts from the first one's impulses: it has almost nothing to do
    assert warm_sweeps < cold_sweeps
    assert second.report.normal_impulse.sum() == pytest.approx(9.81 / 240, rel=1e-4)
    assert abs(second.states.linear[1, 2]) < 1e-4
    assert len(world._cache) == 4
    world.forget(np.array([1]))
    assert len(world._cache) == 0


def test_speculative_contact_that_cannot_close_this_step_is_no_solver_row():
    """A ball 1 cm above the floor at 0.05 m/s cannot touch it within 1/120 s: no row,
    no impulse, velocity untouched; at 2 m/s the same gap closes and the row acts."""
    floor = box('floor', (2.0, 2.0, 0.2), 1.0, static=True)
    ball = sphere('ball', 0.1, 1.0, e=0.0)
    dt, gap = 1 / 120, 0.01
    for speed, solved in ((0.05, 0), (2.0, 1)):
        # the gap before the step is 1 cm; the separation is the one at the current state
        contacts = contact_set(0, 1, [0, 0, 0], [0, 0, 1], gap - speed * dt,
                               kind=ContactKind.PERSISTENT)
        world = World([floor, ball], SolverSettings(), FixedContacts(contacts))
        before = states([[0, 0, -0.1], [0, 0, 0.1 + gap]], [[0, 0, 0], [0, 0, -speed]])
        after = before.copy()
        after.position[1, 2] -= speed * dt
        result = world.step(before, after, dt)
        print(f'approach {speed} m/s: rows {world.timing["rows"]}, impulse '
              f'{result.report.normal_impulse[0]:.4f} N s, vz {result.states.linear[1, 2]:.4f}')
        assert result.report.contacts.count == 1 and world.timing['rows'] == solved
        if solved:
            assert result.report.normal_impulse[0] > 0.0
            assert result.states.position[1, 2] >= 0.1 - 1e-9        # stopped at the floor
        else:
            assert result.report.normal_impulse[0] == 0.0
            assert result.states.linear[1, 2] == -speed


def test_every_solver_tuning_reaches_the_compiled_solver_by_name():
    """config.SOLVER_TUNING is the one source of the solver's tunings: each is handed over
    by name, and the compiled defaults agree with it (no second truth)."""
    from collres_ros.core import _native
    from collres_ros.core.config import SOLVER_TUNING
    from collres_ros.core.detection import DETECTION_ONLY, DETECTION_TUNING
    from collres_ros.core.world import solver_params
    compiled, handed = _native.SolverParams(), solver_params(SolverSettings())
    assert set(DETECTION_ONLY) <= set(DETECTION_TUNING)   # those reach the detector
    for spec in SOLVER_TUNING:
        if spec.name in DETECTION_ONLY:
            assert not hasattr(compiled, spec.name), spec.name
            continue
        assert getattr(compiled, spec.name) == spec.default, spec.name
        assert getattr(handed, spec.name) == spec.default, spec.name
