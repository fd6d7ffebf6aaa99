"""Resolver history rules, quarantine and determinism (core/pipeline.py, core/validation.py)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from fake_world import FakeWorld, GuardingWorld, one_contact

from collres_ros.core.pipeline import FRESH_DT, Resolver
from collres_ros.core.types import BodyInput, BodyStates
from collres_ros.ros.params import scene_from_values

MS = 1_000_000  # ns
T0 = 5_000 * MS


def scene():
    return scene_from_values({
        'bodies': ['floor', 'ball', 'box'],
        'body.floor.shape': 'box', 'body.floor.size': [10.0, 10.0, 0.2],
        'body.floor.static': True, 'body.floor.position': [0.0, 0.0, -0.1],
        'body.ball.shape': 'sphere', 'body.ball.size': [0.1],
        'body.ball.position': [0.0, 0.0, 1.0],
        'body.box.shape': 'box', 'body.box.size': [0.2, 0.2, 0.2],
        'body.box.position': [1.0, 0.0, 0.1],
        'solver.max_dt': 0.5, 'stale_timeout': 0.05})


def make(world=None):
    s = scene()
    world = world or FakeWorld(s.bodies, s.solver)
    return Resolver.for_scene(s, world=world), world


def body(name, z=1.0, vz=0.0, q=(0.0, 0.0, 0.0, 1.0), frame='world', twist_frame='world',
         x=0.0, wz=0.0):
    return BodyInput(name, (x, 0.0, z), q, (0.0, 0.0, vz), (0.0, 0.0, wz), frame, twist_frame)


def test_first_sight_starts_fresh_then_previous_is_last_corrected():
    resolver, world = make()
    first = resolver.resolve(T0, [body('ball', 1.0, -1.0)])
    call = world.calls[-1]
    assert call['dt'] == FRESH_DT
    np.testing.assert_array_equal(call['previous'].position[1], call['current'].position[1])
    assert [1] in world.forgotten
    assert first.names == ['ball'] and [r.reason for r in first.resets] == []

    def lift(states):
        states.position[1, 2] += 0.25   # the "solver" moves the ball
    world.hook = lift
    resolver.resolve(T0 + 4 * MS, [body('ball', 0.99, -1.0)])
    world.hook = None
    out = resolver.resolve(T0 + 8 * MS, [body('ball', 0.98, -1.0)])
    call = world.calls[-1]
    print('dt', call['dt'], 'previous z', call['previous'].position[1, 2])
    assert call['dt'] == pytest.approx(0.004, abs=1e-15)
    assert call['previous'].position[1, 2] == pytest.approx(0.99 + 0.25, abs=1e-12)
    assert call['current'].position[1, 2] == 0.98
    assert out.states.position[0, 2] == 0.98


def test_time_backwards_is_refused_and_a_second_one_later_is_a_new_run():
    resolver, world = make()
    resolver.resolve(T0, [body('ball', 1.0)])
    resolver.resolve(T0 + 4 * MS, [body('ball', 0.9)])
    world.forgotten.clear()
    calls = len(world.calls)
    out = resolver.resolve(T0 + 2 * MS, [body('ball', 0.5)])   # a glitch: nothing changes
    assert [r.reason for r in out.rejected] == ['time_backwards'] and not out.resets
    assert out.names == [] and len(world.calls) == calls and not world.forgotten
    assert resolver.last_stamp[1] == T0 + 4 * MS
    out = resolver.resolve(T0 + 3 * MS, [body('ball', 0.5)])   # behind again, later: a new run
    call = world.calls[-1]
    assert [r.reason for r in out.resets] == ['time_backwards'] and not out.rejected
    assert out.names == ['ball'] and out.states.position[0, 2] == 0.5
    assert call['previous'].position[1, 2] == 0.5 and call['dt'] == FRESH_DT
    assert [1] in world.forgotten
    assert resolver.totals['time_backwards'] == 2


def test_huge_dt_is_a_fresh_start():
    resolver, world = make()
    resolver.resolve(T0, [body('ball', 1.0)])
    out = resolver.resolve(T0 + 2_000 * MS, [body('ball', 0.2)])
    call = world.calls[-1]
    assert [r.reason for r in out.resets] == ['large_gap']
    assert call['previous'].position[1, 2] == 0.2 and call['dt'] == FRESH_DT


@pytest.mark.parametrize('bad, reason', [
    (body('ball', math.nan), 'non_finite'),
    (body('ball', 1.0, vz=math.inf), 'non_finite'),
    (body('ball', q=(0.0, 0.0, 0.0, 0.0)), 'zero_quaternion'),
    (body('ball', q=(0.0, 0.0, 0.0, 1.5)), 'non_unit_quaternion'),
    (body('ball', frame='map'), 'wrong_frame'),
    (body('ball', twist_frame='base_link'), 'wrong_frame'),
])
def test_quarantine_holds_bad_body_and_serves_the_others(bad, reason):
    resolver, world = make()
    resolver.resolve(T0, [body('ball', 1.0, -1.0), body('box', 0.1, x=1.0)])
    out = resolver.resolve(T0 + 4 * MS, [bad, body('box', 0.1, x=1.0)])
    call = world.calls[-1]
    assert [(r.body, r.reason) for r in out.rejected] == [('ball', reason)]
    assert out.names == ['box']
    assert call['active'].tolist() == [True, False, True]
    # held at its last good state, finite
    assert call['current'].position[1, 2] == 1.0 and call['current'].linear[1, 2] == -1.0
    assert all(np.isfinite(getattr(call['current'], f)).all()
               for f in ('position', 'orientation', 'linear', 'angular'))


def test_unknown_and_duplicate_names_are_refused():
    resolver, world = make()
    out = resolver.resolve(T0, [body('ghost'), body('ball', 1.0), body('ball', 2.0),
                                body('box', 0.1, x=1.0)])
    assert sorted((r.body, r.reason) for r in out.rejected) == [
        ('ball', 'duplicate_body'), ('ball', 'duplicate_body'), ('ghost', 'unknown_body')]
    assert out.names == ['box']
    assert resolver.totals['duplicate_body'] == 2 and resolver.totals['unknown_body'] == 1


def test_repeated_stamp_is_refused():
    resolver, world = make()
    resolver.resolve(T0, [body('ball', 1.0)])
    out = resolver.resolve(T0, [body('ball', 0.5)])
    assert [r.reason for r in out.rejected] == ['repeated_stamp'] and out.names == []


def test_near_unit_quaternion_is_normalised():
    resolver, world = make()
    out = resolver.resolve(T0, [body('ball', q=(0.0, 0.0, 0.0, 1.0005))])
    assert not out.rejected
    assert np.linalg.norm(out.states.orientation[0]) == pytest.approx(1.0, abs=1e-15)


def test_body_frame_twist_is_rotated_to_world():
    resolver, world = make()
    half = math.sqrt(0.5)   # 90 deg about z: body x = world y
    item = BodyInput('ball', (0.0, 0.0, 1.0), (0.0, 0.0, half, half), (1.0, 0.0, 0.0),
                     (0.0, 0.0, 0.0), 'world', 'ball')
    out = resolver.resolve(T0, [item])
    np.testing.assert_allclose(world.calls[-1]['current'].linear[1], [0.0, 1.0, 0.0],
                               atol=1e-12)
    assert out.twist_in_body.tolist() == [True]


def test_statics_take_params_pose_unless_published():
    resolver, world = make()
    resolver.resolve(T0, [body('ball', 1.0)])
    assert world.calls[-1]['current'].position[0].tolist() == [0.0, 0.0, -0.1]
    assert world.calls[-1]['active'][0]
    resolver.resolve(T0 + 4 * MS, [body('ball', 1.0), body('floor', z=-0.3)])
    assert world.calls[-1]['current'].position[0].tolist() == [0.0, 0.0, -0.3]


def test_time_of_impact_is_absolute():
    resolver, world = make()
    resolver.resolve(T0, [body('ball', 1.0)])
    world.report = one_contact(0, 1, 0.25)
    out = resolver.resolve(T0 + 4 * MS, [body('ball', 0.9)])
    print('toi_ns', out.toi_ns, 'expected', T0 + MS)
    assert out.toi_ns.tolist() == [T0 + MS]
    assert out.contact_names(0) == ('floor', 'ball')


def test_non_finite_result_passes_input_through():
    resolver, world = make()
    resolver.resolve(T0, [body('ball', 1.0)])
    world.hook = lambda states: states.linear.__setitem__((1, 0), math.nan)
    out = resolver.resolve(T0 + 4 * MS, [body('ball', 0.9, -1.0)])
    assert [r.reason for r in out.rejected] == ['non_finite_result']
    assert out.states.position[0, 2] == 0.9 and out.states.linear[0, 2] == -1.0
    assert np.isfinite(out.states.linear).all()


def test_stale_bodies_are_reported():
    resolver, world = make()
    resolver.resolve(T0, [body('ball', 1.0), body('box', 0.1, x=1.0)])
    out = resolver.resolve(T0 + 40 * MS, [body('ball', 1.0)])
    assert out.stale == []
    out = resolver.resolve(T0 + 80 * MS, [body('ball', 1.0)])
    assert out.stale == ['box']


def test_runtime_settings_and_materials_reach_the_world():
    resolver, world = make()
    resolver.settings = resolver.settings.with_values(velocity_iterations=33)
    resolver.set_material('ball', restitution=0.1)
    resolver.resolve(T0, [body('ball', 1.0)])
    assert world.calls[-1]['settings'].velocity_iterations == 33
    assert world.materials == {1: {'restitution': 0.1}}


def _world_available() -> bool:
    try:
        import collres_ros.core.world  # noqa: F401
    except ImportError:
        return False
    return True


@pytest.mark.skipif(not _world_available(), reason='core/world.py not there yet')
def test_real_world_is_deterministic_bit_for_bit():
    """Two resolvers fed the same falling-ball inputs give identical states and contacts."""
    runs = []
    for _ in range(2):
        resolver = Resolver.for_scene(scene())
        z, v, dt = 0.3, 0.0, 1 / 240
        outputs = []
        for k in range(200):
            v -= 9.81 * dt
            z += v * dt
            out = resolver.resolve(T0 + int(round(k * dt * 1e9)), [body('ball', z, v)])
            z, v = out.states.position[0, 2], out.states.linear[0, 2]
            outputs.append((out.states.position.tobytes(), out.states.linear.tobytes(),
                            out.report.normal_impulse.tobytes(), out.toi_ns.tobytes()))
        runs.append(outputs)
    impacts = sum(1 for o in runs[0] if len(o[2]))
    print('steps with contacts', impacts)
    assert impacts > 0
    assert runs[0] == runs[1]


def test_a_non_finite_result_the_world_repaired_is_reported_once():
    s = scene()
    resolver, world = make(GuardingWorld(s.bodies, s.solver))
    resolver.resolve(T0, [body('ball', 1.0)])
    world.hook = lambda states: states.linear.__setitem__((1, 0), math.nan)
    out = resolver.resolve(T0 + 4 * MS, [body('ball', 0.9, -1.0)])
    print([(r.body, r.reason) for r in out.rejected], dict(resolver.totals))
    assert [(r.body, r.reason) for r in out.rejected] == [('ball', 'non_finite_result')]
    assert resolver.totals['non_finite_result'] == 1
    assert out.states.position[0, 2] == 0.9 and np.isfinite(out.states.linear).all()


def test_the_real_world_guard_is_counted(monkeypatch):
    class PoisonedSolver:
        """The compiled solver, then the movable bodies' corrected velocities set to NaN."""

        def __init__(self, real):
            self.real, self.cache = real, real.cache

        def step(self, **arrays):
            result = self.real.step(**arrays)
            arrays['out'][2][arrays['movable']] = math.nan
            return result
    resolver = Resolver.for_scene(scene())
    resolver.resolve(T0, [body('ball', 0.09)])      # resting in the floor: a contact
    monkeypatch.setattr(resolver.world, '_solver', PoisonedSolver(resolver.world._solver))
    out = resolver.resolve(T0 + 4 * MS, [body('ball', 0.09)])
    assert out.report.contacts.count > 0, 'no contact: the guard was not exercised'
    print([(r.body, r.reason) for r in out.rejected], dict(resolver.totals))
    assert [(r.body, r.reason) for r in out.rejected] == [('ball', 'non_finite_result')]
    assert resolver.totals['non_finite_result'] == 1
    assert np.isfinite(out.states.linear).all()


def test_a_name_list_changed_in_place_is_looked_up_again():
    """The resolver keeps the last name list's lookup (a stream repeats it): a list that
    changes (here the same list object, reordered and extended in place) is looked up again,
    each body getting its own state and the unknown name refused."""
    from collres_ros.core.types import InputBatch
    resolver, world = make()
    names = ['ball', 'box']
    values = np.array([[0.0, 0.0, 1.0, 0, 0, 0, 1, 0, 0, 0, 0, 0, 0],
                       [1.0, 0.0, 0.1, 0, 0, 0, 1, 0, 0, 0, 0, 0, 0]], float)
    first = resolver.resolve(T0, InputBatch(names, values, 'world', 'world'))
    assert first.names == ['ball', 'box'] and not first.rejected
    names.reverse()
    names.append('ghost')
    swapped = np.vstack([values[::-1], values[:1]])
    out = resolver.resolve(T0 + 4 * MS, InputBatch(names, swapped, 'world', 'world'))
    assert out.names == ['box', 'ball']
    assert [(r.body, r.reason) for r in out.rejected] == [('ghost', 'unknown_body')]
    call = world.calls[-1]
    assert call['current'].position[1, 2] == 1.0 and call['current'].position[2, 2] == 0.1


@pytest.mark.skipif(not _world_available(), reason='core/world.py not there yet')
def test_inputs_in_scene_order_and_shuffled_give_the_same_answers():
    """A stream of consecutive scene bodies in scene order is scattered and gathered as
    blocks (``CheckedInputs.rows`` a slice), any other order row by row: the ball dropped on
    the box and the box at rest get bit-identical states and contacts either way, and the
    answer lists the bodies in input order."""
    from collres_ros.core.types import InputBatch
    runs = []
    for order in (['ball', 'box'], ['box', 'ball']):
        resolver = Resolver.for_scene(scene())
        state = {'ball': [1.0, 0.0, 0.35, 0, 0, 0, 1, 0, 0, 0, 0, 0, 0],
                 'box': [1.0, 0.0, 0.1, 0, 0, 0, 1, 0, 0, 0, 0, 0, 0]}
        dt, outputs = 1 / 240, []
        for k in range(120):
            for row in state.values():          # semi-implicit Euler with gravity
                row[9] -= 9.81 * dt
                row[2] += row[9] * dt
            values = np.array([state[n] for n in order], float)
            out = resolver.resolve(T0 + int(round(k * dt * 1e9)),
                                   InputBatch(list(order), values, 'world', 'world'))
            assert out.names == order and not out.rejected
            for j, name in enumerate(order):
                state[name] = [*out.states.position[j], *out.states.orientation[j],
                               *out.states.linear[j], *out.states.angular[j]]
            outputs.append(({n: np.array(v).tobytes() for n, v in state.items()},
                            out.report.normal_impulse.tobytes(), out.report.contacts.count))
        runs.append(outputs)
    assert sum(1 for o in runs[0] if o[2]) > 0, 'no contact: nothing was resolved'
    assert runs[0] == runs[1]


def test_the_world_answers_the_resolvers_rows_as_it_answers_separate_arrays():
    """World.step takes the resolver's (N, 13) rows as they are (the compiled detection,
    solve, hold-back and sleep islands read their column views): a stack of boxes dropped
    on a floor, stepped from rows and from four separate C-contiguous arrays per state,
    gives the same bits every step, awake, in contact, and asleep."""
    from collres_ros.core.world import World
    values = {'bodies': ['floor'] + [f'box{k}' for k in range(4)],
              'body.floor.shape': 'box', 'body.floor.size': [4.0, 4.0, 0.2],
              'body.floor.static': True, 'body.floor.position': [0.0, 0.0, -0.1]}
    for k in range(4):
        values[f'body.box{k}.shape'] = 'box'
        values[f'body.box{k}.size'] = [0.2, 0.2, 0.2]
        values[f'body.box{k}.position'] = [0.03 * k, 0.0, 0.1 + 0.21 * k + 0.02]
    s = scene_from_values(values)
    worlds = [World(s.bodies, s.solver), World(s.bodies, s.solver)]
    rows = np.concatenate([s.initial.position, s.initial.orientation, s.initial.linear,
                           s.initial.angular], axis=1)
    dynamic = worlds[0].dynamic
    dt, gravity = 1.0 / 60.0, np.array([0.0, 0.0, -9.81])
    asleep = contacts = 0
    for _ in range(150):
        current = rows.copy()
        current[dynamic, 7:10] += gravity * dt
        current[dynamic, 0:3] += current[dynamic, 7:10] * dt
        from_rows = worlds[0].step(rows, current, dt)
        columns = ((0, 3), (3, 7), (7, 10), (10, 13))
        arrays = [np.ascontiguousarray(rows[:, a:b]) for a, b in columns]
        now = [np.ascontiguousarray(current[:, a:b]) for a, b in columns]
        from_arrays = worlds[1].step(BodyStates(*arrays), BodyStates(*now), dt)
        assert from_rows.values.tobytes() == from_arrays.values.tobytes()
        assert (from_rows.sleeping == from_arrays.sleeping).all()
        for name in ('normal_impulse', 'friction_impulse', 'state'):
            assert getattr(from_rows.report, name).tobytes() == \
                getattr(from_arrays.report, name).tobytes()
        rows = from_rows.values
        asleep += int(from_rows.sleeping.any())
        contacts += int(from_rows.report.contacts.count > 0)
    assert contacts > 100 and asleep > 10            # both paths were taken
    assert abs(rows[dynamic, 2].min() - 0.1) < 0.01   # the stack rests on the floor
