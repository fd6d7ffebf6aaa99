"""Islands and sleeping (core/sleep.py, src/islands.h): the rules, each stated as a law.

A box resting on the floor, integrated with gravity by test/core/integrator.py (upstream
keeps integrating: a sleeping body's input is the held pose + gravity dt, which must not
wake it):

* it falls asleep after ``time_to_sleep`` of answers slower than ``sleep_threshold``;
* asleep, its answer is the held pose and zero twist, equal within 1e-9 to what the solver
  (sleeping off) answers the same inputs, and no detection runs;
* a lost input (the node's dt spans two upstream periods) does not wake it;
* it wakes in the step on a push above the threshold (not below), a teleport, a touch (a
  falling ball's swept bounds, before the contact: the impact obeys the same laws as
  without sleeping, and a second island far away stays asleep), a material, settings or
  filter change, a body reset or removed, and a clock jump;
* a step without its input (held: fixed, as a sleeper is) wakes nothing, but a body back
  from held and moved wakes the islands its swept bounds touch;
* a body restarted fresh (back after a missed step) wakes only its own island and those it
  sweeps from where it was held to its input (a kinematic one only if it moved).

A node that falls behind drops inputs, and the step it takes next spans k periods; its
source either integrated the last answer for one period (it integrates each answer it
gets, as bench/bench_latency.py's simulator) or for k (it kept integrating its own
state). Either way each pile falls asleep within 8 s (with every period answered they take
1.1-3.1 s), and a sleeping pile stays
asleep and in place. No ratio to the steady time is asserted: one pile's sleep time is
chaotic (1.9 to 6.9 s at 30 Hz for three jitters of the same pile), and over 30 piles with
steps of 1-4 periods the mean took 2.03-2.07 times the steady one while groups of three
ranged 1.3-3.3 times:
the warm start and the sweeps follow the load the input carries (one period of gravity
is one period's impulses, whatever dt says), not dt alone.

And a pile of 100 cubes dropped into a bin (``bench/pile.py``: columns of 6-7 cubes whose
face contacts each hold 4 points) falls asleep within 5 s at 30, 120 and 240 Hz: the
position pass's split impulses push each contact out in one sweep, 0.4 of the penetration
a step, where 4 sweeps removing half of it moved and tilted whole columns at once, which
fed a sway (the top cubes at 0.15 m/s) that never let the pile sleep.
"""

from __future__ import annotations

import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from collres_ros.core.config import SolverSettings
from collres_ros.core.detection import Detection
from collres_ros.core.pipeline import Resolver
from collres_ros.core.types import BodySpec, BodyStates, ContactState, InputBatch
from collres_ros.core.world import World

from contacts import box, sphere, states  # noqa: I100
from integrator import Simulation

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / 'bench'))
from pile import integrate, make_pile  # noqa: E402

RATE = 100.0
SIZE = 0.2


def floor() -> BodySpec:
    return BodySpec('floor', 'plane', (0.0, 0.0, 1.0, 0.0), static=True,
                    static_friction=0.5, kinetic_friction=0.3)


class CountingDetection(Detection):
    """The real detector, counting its calls."""

    calls = 0

    def detect(self, previous, current, active=None, threads=1, dt=0.0):
        self.calls += 1
        return super().detect(previous, current, active, threads, dt=dt)


def resting_boxes(xs=(0.0,), settings: SolverSettings | None = None,
                  extra: list | None = None) -> Simulation:
    """Boxes resting on the floor at these x (and ``extra`` bodies: (spec, position))."""
    extra = extra or []
    bodies = [floor()] + [box(f'box{k}', (SIZE,) * 3, 1.0, mu_s=0.5, mu_k=0.3)
                          for k in range(len(xs))] + [spec for spec, _ in extra]
    positions = [[0, 0, 0]] + [[x, 0, SIZE / 2] for x in xs] + [p for _, p in extra]
    return Simulation(bodies, states(positions, np.zeros((len(bodies), 3))), RATE,
                      settings or SolverSettings())


def run_until_asleep(sim: Simulation, limit: float = 3.0) -> int:
    for k in range(int(limit * RATE)):
        result = sim.step()
        if result.sleeping is not None and result.sleeping[1:].all():
            return k
    raise AssertionError('never fell asleep')


def step_with(sim: Simulation, change=None, **kwargs):
    """One step with the integrator's input, changed by ``change(current)`` first."""
    current = sim.integrate(sim.state)
    if change is not None:
        change(current)
    result = sim.world.step(sim.state, current, sim.dt, **kwargs)
    sim.state = result.states
    return result


@pytest.mark.parametrize('time_to_sleep', [0.25, 0.5])
def test_falls_asleep_after_time_to_sleep_under_the_threshold(time_to_sleep: float) -> None:
    sim = resting_boxes(settings=SolverSettings(time_to_sleep=time_to_sleep))
    flags, speeds = [], []
    for _ in range(int(2 * time_to_sleep * RATE)):
        result = sim.step()
        flags.append(bool(result.sleeping[1]))
        speeds.append(np.linalg.norm(result.states.linear[1]))
    first = flags.index(True)
    print(f'asleep at step {first} ({(first + 1) / RATE:.2f} s), time_to_sleep {time_to_sleep}')
    assert max(speeds[:first]) < SolverSettings().sleep_threshold   # still from the start
    assert abs((first + 1) / RATE - time_to_sleep) <= 1.0 / RATE + 1e-9
    assert all(flags[first:]), 'held input (held pose + gravity dt) woke it'
    assert not sim.world.sleep.counts()['awake_islands']


def test_a_moving_body_never_sleeps() -> None:
    """A box kept sliding faster than the threshold (no friction) stays awake."""
    sim = Simulation([BodySpec('floor', 'plane', (0.0, 0.0, 1.0, 0.0), static=True,
                               static_friction=0.0, kinetic_friction=0.0),
                      box('box', (SIZE,) * 3, 1.0, mu_s=0.0, mu_k=0.0)],
                     states([[0, 0, 0], [0, 0, SIZE / 2]], [[0, 0, 0], [0.06, 0, 0]]), RATE)
    assert not any(sim.step().sleeping[1] for _ in range(200))


def _box_on_a_slope(accel: float, mu: float) -> Simulation:
    """A box at rest on a plane tilted so that, without friction, it slides down at ``accel``
    (m/s^2, g sin theta); friction coefficient ``mu`` on both."""
    theta = np.arcsin(accel / 9.81)
    normal = np.array([-np.sin(theta), 0.0, np.cos(theta)])
    plane = BodySpec('slope', 'plane', (*normal, 0.0), static=True, restitution=0.0,
                     static_friction=mu, kinetic_friction=mu)
    block = box('box', (SIZE,) * 3, 1.0, mu_s=mu, mu_k=mu)
    initial = states([[0, 0, 0], SIZE / 2 * normal], np.zeros((2, 3)))
    initial.orientation[1] = [0.0, np.sin(-theta / 2), 0.0, np.cos(-theta / 2)]   # on its face
    return Simulation([plane, block], initial, RATE)


@pytest.mark.parametrize('accel', [1e-3, 1e-2])
def test_a_slowly_accelerating_body_never_sleeps(accel: float) -> None:
    """A box sliding from rest down a frictionless slope at 1 or 10 mm/s^2 stays under the
    threshold for 3 s or more (50 or 5 s), yet it is not at rest: an unbalanced load speeds
    it up every step, so it never sleeps and slides 0.5 a t^2 (within 1 %). On the same
    slope with friction (mu 0.5 > tan theta) it holds, a balanced load, and sleeps after
    time_to_sleep."""
    sim = _box_on_a_slope(accel, 0.0)
    start = sim.state.position[1].copy()
    steps = int(3.0 * RATE)
    assert not any(sim.step().sleeping[1] for _ in range(steps))
    assert np.linalg.norm(sim.state.linear[1]) < SolverSettings().sleep_threshold
    slid = np.linalg.norm(sim.state.position[1] - start)
    print(f'a {accel} m/s^2: slid {slid * 1e3:.3f} mm in 3 s, law {0.5 * accel * 9e3:.3f}')
    assert slid == pytest.approx(0.5 * accel * 3.0 ** 2, rel=0.01)
    held = _box_on_a_slope(accel, 0.5)
    first = run_until_asleep(held)
    assert (first + 1) / RATE <= SolverSettings().time_to_sleep + 2.0 / RATE


def test_sleeping_answer_equals_the_solvers_for_a_resting_body_and_skips_detection() -> None:
    sim = resting_boxes()
    detection = CountingDetection(sim.world.specs, SolverSettings(sleeping=False))
    twin = World(sim.world.specs, SolverSettings(sleeping=False), detector=detection)
    counting = CountingDetection(sim.world.specs, sim.world.settings)
    sim.world = World(sim.world.specs, sim.world.settings, detector=counting)
    asleep_steps = 0
    for _ in range(150):
        previous, current = sim.state, sim.integrate(sim.state)
        ours = sim.world.step(previous, current, sim.dt)
        theirs = twin.step(previous, current, sim.dt)
        sim.state = ours.states
        if ours.sleeping[1]:
            asleep_steps += 1
            calls = counting.calls
            np.testing.assert_array_equal(ours.states.linear[1], 0.0)
            np.testing.assert_array_equal(ours.states.angular[1], 0.0)
            if asleep_steps > 1:   # after the step it fell asleep in: the held pose
                np.testing.assert_array_equal(ours.states.position[1], previous.position[1])
                np.testing.assert_array_equal(ours.states.orientation[1],
                                              previous.orientation[1])
            # (the awake solver's resting answer keeps the manifold block's regularisation,
            # 1e-8 of the step's change g dt: a few nm/s)
            for name in ('position', 'orientation', 'linear', 'angular'):
                np.testing.assert_allclose(getattr(ours.states, name)[1],
                                           getattr(theirs.states, name)[1], rtol=0, atol=1e-8)
            # its contacts are still reported (from the next step on: held, SLEEPING)
            assert ours.report.contacts.count == 4
            assert (ours.report.state == ContactState.SLEEPING).all() == (asleep_steps > 1)
        else:
            calls = None
        if calls is not None and asleep_steps > 1:
            assert counting.calls == calls, 'a sleeping island was detected'
    assert asleep_steps > 50
    print(f'{asleep_steps} steps asleep, detection ran {counting.calls} times of 150')
    assert counting.calls <= 150 - asleep_steps + 1


def _push(v):
    def change(current):
        current.linear[1] += v
    return change


def test_wakes_on_a_push_above_the_threshold_not_below() -> None:
    sim = resting_boxes()
    run_until_asleep(sim)
    assert step_with(sim, _push([0.02, 0.0, 0.0])).sleeping[1]     # below 0.05 m/s
    result = step_with(sim, _push([0.5, 0.0, 0.0]))
    assert not result.sleeping[1]
    assert result.states.linear[1, 0] > 0.4                       # pushed, friction 0.03
    assert (result.report.state != ContactState.SLEEPING).all()


def test_a_lost_input_does_not_wake_it() -> None:
    """An input lost on the way: the node's dt spans two of the upstream's periods while
    the upstream still integrated one period from the held answer (held twist + g dt)."""
    sim = resting_boxes()
    run_until_asleep(sim)
    for span in (2, 3):
        current = sim.integrate(sim.state)
        result = sim.world.step(sim.state, current, span * sim.dt)
        assert result.sleeping[1], f'woken by a dt of {span} periods'
        sim.state = result.states
    # and a push over such a step still wakes it
    current = sim.integrate(sim.state)
    current.linear[1, 0] += 0.5
    assert not sim.world.step(sim.state, current, 2 * sim.dt).sleeping[1]


def test_an_input_from_a_late_answer_does_not_wake_it() -> None:
    """An answer that came late: the upstream integrated its own state from the held one
    k times (k - 1 periods of its own, then the usual one: k (k + 1) / 2 g dt^2 down,
    moving at k g dt) while the node's dt is one period. Up to ``SLEEP_LATE_STEPS`` the
    island stays asleep, answered at its held rest (8ac80a2 woke it at k = 2 and solved it
    cold: a 100-body pile at 100 Hz took up to 4 cm/s and was awake 1.1 s later); beyond
    that, or with a push on top, it wakes."""
    from collres_ros.core.config import SLEEP_LATE_STEPS
    sim = resting_boxes()
    run_until_asleep(sim)
    held = sim.state.copy()

    def late(k: int, push: float = 0.0):
        current = sim.state
        for _ in range(k):
            current = sim.integrate(current)
        current.linear[1, 0] += push
        return sim.world.step(sim.state, current, sim.dt)

    for k in range(2, SLEEP_LATE_STEPS + 1):
        result = late(k)
        assert result.sleeping[1], f'woken by an answer {k - 1} periods late'
        np.testing.assert_array_equal(result.states.position[1], held.position[1])
        np.testing.assert_array_equal(result.states.linear[1], 0.0)
        sim.state = result.states
    assert not late(2, push=0.5).sleeping[1]
    sim = resting_boxes()
    run_until_asleep(sim)
    assert not late(SLEEP_LATE_STEPS + 1).sleeping[1]


def test_wakes_on_a_teleport() -> None:
    sim = resting_boxes()
    run_until_asleep(sim)

    def teleport(current):
        current.position[1, 0] += 0.05

    result = step_with(sim, teleport)
    assert not result.sleeping[1]
    assert (result.report.state != ContactState.SLEEPING).all()   # solved again


def test_a_falling_ball_wakes_only_the_island_it_lands_on_and_bounces_as_without_sleep(
) -> None:
    """Two sleeping boxes 1 m apart; a ball dropped on the first. The first wakes no later
    than the step of contact, the second never; the bounce is the one without sleeping
    (the box on the inelastic floor takes part: the ball keeps less than e of its speed)."""
    r, e = 0.05, 0.6
    ball = sphere('ball', r, 0.2, e=e)
    runs = {}
    for sleeping in (True, False):
        sim = resting_boxes((0.0, 1.0), SolverSettings(sleeping=sleeping))
        if sleeping:
            run_until_asleep(sim)
        else:
            for _ in range(int(1.5 * RATE)):
                sim.step()
        rested = sim.state.copy()
        bodies = sim.world.specs + [ball]
        drop = Simulation(bodies, states(np.vstack([rested.position, [[0.0, 0.0, 0.6]]]),
                                         np.zeros((4, 3))), RATE, sim.world.settings)
        drop.state.orientation[:3] = rested.orientation
        if sleeping:   # carry the sleep over: the boxes' world, plus the ball
            drop.world = World(bodies, sim.world.settings)
            for _ in range(int(0.6 * RATE)):       # fall asleep again before the drop
                drop.world.step(drop.state, drop.integrate(drop.state), drop.dt)
        trace = []
        for k in range(int(0.8 * RATE)):
            before = drop.state.copy()
            result = drop.step()
            c = result.report.contacts
            ball_box = [(int(a), int(b)) for a, b in zip(c.body_a, c.body_b)
                        if {int(a), int(b)} == {1, 3}]
            trace.append((k, before, result, bool(ball_box)))
        runs[sleeping] = trace
    sleep_trace, plain = runs[True], runs[False]
    hit = next(k for k, _, _, touching in plain if touching)
    assert next(k for k, _, _, touching in sleep_trace if touching) == hit
    _, before, result, _ = sleep_trace[hit]
    assert before is not None
    woke = next(k for k, _, res, _ in sleep_trace if not res.sleeping[1])
    print(f'ball touches at step {hit}, box0 wakes at step {woke}')
    assert woke <= hit
    assert all(res.sleeping[2] for _, _, res, _ in sleep_trace), 'the far island woke'
    # the bounce: as without sleeping, restitution along the normal, no energy gain
    bounce = next(k for k, _, res, _ in plain if res.states.linear[3, 2] > 0.0)
    assert bounce >= hit
    impacts = sleep_trace[bounce][2].report.state
    assert (impacts == ContactState.IMPACT).any()
    v_in = sleep_trace[bounce - 1][2].states.linear[3, 2]   # last answer before the bounce
    v_out = sleep_trace[bounce][2].states.linear[3, 2]
    v_plain = plain[bounce][2].states.linear[3, 2]
    print(f'ball {v_in:.4f} -> {v_out:.4f} m/s at step {bounce} (without sleeping '
          f'{v_plain:.4f})')
    assert v_out == pytest.approx(v_plain, abs=1e-6)
    assert 0.0 < v_out <= e * abs(v_in)      # restitution along the normal at most e
    gap = min(res.states.position[3, 2] - r - res.states.position[1, 2] - SIZE / 2
              for _, _, res, _ in sleep_trace)   # ball above the box's top face, answers
    print(f'smallest gap ball-box {gap:.2e} m')
    assert gap >= -SolverSettings().linear_slop - 1e-9


@pytest.mark.parametrize('change', ['material', 'settings', 'filter', 'forget', 'clock'])
def test_wakes_on_a_change(change: str) -> None:
    sim = resting_boxes()
    run_until_asleep(sim)
    world = sim.world
    kwargs = {}
    if change == 'material':
        world.set_material(1, restitution=0.3)
    elif change == 'settings':
        world.settings = replace(world.settings, velocity_iterations=12)
    elif change == 'filter':
        world.collision_filter = world.collision_filter.ignoring()
    elif change == 'forget':
        world.forget(np.array([1]))
    else:   # a clock jump
        kwargs['fresh'] = True
    assert not step_with(sim, **kwargs).sleeping[1]


def test_a_body_held_for_a_step_wakes_nothing() -> None:
    """A step without a body's input (a message of some bodies) holds that body where it is,
    fixed, as a sleeper is held: two boxes asleep stay asleep, the one held and the one given
    its input, at their held poses, and so in the steps after it. (7039d81 woke every island
    on any change of the held bodies: a message of some bodies woke the whole scene.)"""
    sim = resting_boxes(xs=(0.0, 1.0))
    run_until_asleep(sim)
    held = sim.state.copy()

    def holding(active):   # no input: the resolver gives a held body its last state
        def change(current):
            for k in np.flatnonzero(~np.array(active)):
                current.position[k], current.orientation[k] = sim.state.position[k], \
                    sim.state.orientation[k]
                current.linear[k] = current.angular[k] = 0.0
        return change

    for active in ([True, False, True], [True, True, False], [True, True, True]):
        result = step_with(sim, holding(active), active=np.array(active))
        assert result.sleeping[1:].all(), f'woken by a step with inputs {active}'
        np.testing.assert_array_equal(result.states.position, held.position)
        np.testing.assert_array_equal(result.states.linear, 0.0)
    assert sim.world.sleep.counts()['sleeping_bodies'] == 2


def test_a_support_back_from_held_and_moved_wakes_what_it_carried() -> None:
    """A box falls asleep on a box whose input was withheld (held: fixed, as a static
    support); when that support's input comes back elsewhere, it is a moving body: its swept
    bounds wake the box it carried, which is solved again in that step."""
    bodies = [floor(), box('below', (SIZE,) * 3, 1.0, mu_s=0.5, mu_k=0.3),
              box('above', (SIZE,) * 3, 1.0, mu_s=0.5, mu_k=0.3)]
    sim = Simulation(bodies, states([[0, 0, 0], [0, 0, SIZE / 2], [0, 0, 1.5 * SIZE]],
                                    np.zeros((3, 3))), RATE)
    held = sim.state.copy()

    def below_held(current):   # no input: the resolver gives a held body its last state
        current.position[1], current.orientation[1] = held.position[1], held.orientation[1]
        current.linear[1] = current.angular[1] = 0.0

    for _ in range(int(2 * RATE)):
        result = step_with(sim, below_held, active=np.array([True, False, True]))
        if result.sleeping[2]:
            break
    assert result.sleeping[2] and not result.sleeping[1]

    def support_gone(current):
        current.position[1, 0] += 3 * SIZE   # the support's input: moved out from under it,
        current.linear[1] = 0.0              # at rest there (no jolt of its own)

    result = step_with(sim, support_gone)
    assert not result.sleeping[2], 'left asleep where its support was'
    assert (result.report.state != ContactState.SLEEPING).all()   # solved again


def _stack_and_ball(ball_at):
    """A resolver of two boxes stacked on the floor at x = 0 (one island) and a ball at
    ``ball_at`` (m), the source integrating each answer (bench/pile.py's integrator): run at
    RATE until the stack sleeps, with the ball still falling, awake. Returns the resolver,
    the last answer's rows (box below, box above, ball), the stamp."""
    bodies = [floor(), box('below', (SIZE,) * 3, 1.0, mu_s=0.5, mu_k=0.3),
              box('above', (SIZE,) * 3, 1.0, mu_s=0.5, mu_k=0.3), sphere('ball', 0.1, 1.0)]
    resolver = Resolver(bodies, SolverSettings())
    names = ['below', 'above', 'ball']
    answer = states([[0, 0, SIZE / 2], [0, 0, 1.5 * SIZE], ball_at], np.zeros((3, 3)))
    stamp = 10**12
    for _ in range(int(2 * RATE)):
        stamp += int(round(1e9 / RATE))
        step = resolver.resolve(stamp, _batch(names, integrate(answer, np.ones(3, bool),
                                                               1 / RATE)))
        answer = step.states
        if step.sleeping[:2].all():
            break
    assert step.sleeping[:2].all() and not step.sleeping[2], 'the stack never fell asleep'
    return resolver, answer, stamp


def _arrays(given: BodyStates):
    return given.position, given.orientation, given.linear, given.angular


def _batch(names, given: BodyStates, rows=slice(None)) -> InputBatch:
    values = np.hstack(_arrays(given))
    return InputBatch(list(np.array(names)[rows]), values[rows], 'world', 'world')


@pytest.mark.parametrize('back_at', ['its_own_path', 'on_the_stack'])
def test_a_body_restarted_fresh_wakes_only_what_it_touches(back_at: str) -> None:
    """An awake ball, falling far from a sleeping stack of two boxes, misses a step (a
    message of the stack alone): when it comes back it restarts fresh (its last state is
    not the previous step's). It moves in that step from where it was held: the islands its
    swept bounds touch wake, no other. Back on its own path, the stack stays asleep, answered
    at its held rest (7039d81 woke every island on any fresh restart: the whole scene woke
    whenever a message had left out an awake body); back on top of the stack (its source
    moved it while the node did not hear it), the stack wakes and is solved in that step."""
    resolver, answer, stamp = _stack_and_ball([3.0, 0.0, 20.0])
    rest = answer.position[:2].copy()
    names = ['below', 'above', 'ball']
    source = integrate(answer, np.ones(3, bool), 1 / RATE)   # the source's own state
    stamp += int(round(1e9 / RATE))
    step = resolver.resolve(stamp, _batch(names, source, slice(0, 2)))   # ball left out
    assert step.sleeping.all(), 'a step that held the ball woke the stack'
    for mine, answered in zip(_arrays(source), _arrays(step.states)):
        mine[:2] = answered   # the stack's answer, the ball's own state: integrated
    source = integrate(source, np.ones(3, bool), 1 / RATE)
    if back_at == 'on_the_stack':
        source.position[2] = [0.0, 0.0, 2 * SIZE + 0.1 + 0.005]   # 5 mm above the top box
    stamp += int(round(1e9 / RATE))
    step = resolver.resolve(stamp, _batch(names, source))
    assert not step.sleeping[2]
    if back_at == 'its_own_path':
        assert step.sleeping[:2].all(), 'the ball\'s restart far away woke the stack'
        np.testing.assert_array_equal(step.states.position[:2], rest)
        np.testing.assert_array_equal(step.states.linear[:2], 0.0)
        assert resolver.world.sleep.counts()['sleeping_bodies'] == 2
    else:
        assert not step.sleeping[:2].any(), 'the ball landed on a stack left asleep'
        assert (step.report.state != ContactState.SLEEPING).all()   # solved in the step


@pytest.mark.parametrize('back_at', ['where_it_was', 'moved_onto_the_box'])
def test_a_kinematic_body_restarted_fresh_wakes_what_it_touches_only_if_it_moved(
        back_at: str) -> None:
    """A kinematic paddle (static, published) stands 5 mm beside a sleeping box, misses a
    step and comes back, restarting fresh: where it was, it moved nothing and the box sleeps
    on, at its held rest, as on any step in which a static body keeps its pose (59f1d0c woke
    every island on a fresh restart); moved onto the box, it wakes it in that step."""
    bodies = [floor(), box('resting', (SIZE,) * 3, 1.0, mu_s=0.5, mu_k=0.3),
              box('paddle', (SIZE,) * 3, 1.0, static=True)]
    resolver = Resolver(bodies, SolverSettings())
    names = ['resting', 'paddle']
    answer = states([[0, 0, SIZE / 2], [SIZE + 0.005, 0, SIZE / 2]], np.zeros((2, 3)))
    stamp = 10**12
    for _ in range(int(2 * RATE)):
        stamp += int(round(1e9 / RATE))
        given = integrate(answer, np.array([True, False]), 1 / RATE)
        step = resolver.resolve(stamp, _batch(names, given))
        answer = step.states
        if step.sleeping[0]:
            break
    assert step.sleeping[0], 'the box never fell asleep'
    rest = answer.position[0].copy()
    stamp += int(round(1e9 / RATE))
    step = resolver.resolve(stamp, _batch(names, integrate(answer, np.array([True, False]),
                                                           1 / RATE), slice(0, 1)))
    assert step.sleeping[0], 'a step that held the paddle woke the box'
    given = integrate(answer, np.array([True, False]), 1 / RATE)
    given.position[0] = step.states.position[0]
    if back_at == 'moved_onto_the_box':
        given.position[1] = [0.0, 0.0, 1.5 * SIZE + 0.005]
    stamp += int(round(1e9 / RATE))
    step = resolver.resolve(stamp, _batch(names, given))
    if back_at == 'where_it_was':
        assert step.sleeping[0], 'the paddle\'s restart where it stood woke the box'
        np.testing.assert_array_equal(step.states.position[0], rest)
    else:
        assert not step.sleeping[0], 'the paddle moved onto a box left asleep'


def test_off_never_sleeps() -> None:
    sim = resting_boxes(settings=SolverSettings(sleeping=False))
    assert all(sim.step().sleeping is None for _ in range(100))


@pytest.mark.parametrize('rate', [30.0, 120.0, 240.0])
def test_a_pile_of_cubes_falls_asleep(rate: float) -> None:
    bodies, initial = make_pile(100, kind='cubes')
    sim = Simulation(bodies, initial, rate)
    dynamic = sim.world.dynamic
    for k in range(int(5.0 * rate)):
        result = sim.step()
        if result.sleeping[dynamic].all():
            print(f'{rate:g} Hz: asleep after {(k + 1) / rate:.2f} s')
            return
    reach = 0.5 * np.linalg.norm([0.1] * 3)
    speed = np.linalg.norm(sim.state.linear, axis=1) + np.linalg.norm(sim.state.angular,
                                                                      axis=1) * reach
    raise AssertionError(f'{rate:g} Hz: awake after 5 s, fastest point {speed.max():.3f} m/s')


def _asleep_after(style: str, seed: int, limit: float = 12.0,
                  periods: int = 4) -> tuple[float, Simulation]:
    """A pile of 100 cubes dropped at 30 Hz, each step spanning k = 1..``periods`` periods
    at random (seeded), its input the last answer integrated for one period (``one``) or
    for k (``k``): the time until every body sleeps (``limit`` when it never does)."""
    bodies, initial = make_pile(100, seed=seed, kind='cubes')
    sim = Simulation(bodies, initial, 30.0)
    dynamic = sim.world.dynamic
    rng = np.random.default_rng(seed)
    elapsed = 0.0
    while elapsed < limit:
        k = int(rng.integers(1, periods + 1)) if elapsed > 0.0 else 1
        current = sim.state
        for _ in range(k if style == 'k' else 1):
            current = sim.integrate(current)
        result = sim.world.step(sim.state, current, k * sim.dt)
        sim.state = result.states
        elapsed += k * sim.dt
        if result.sleeping[dynamic].all():
            break
    return elapsed, sim


SEEDS = (1, 2, 3)   # piles (bench/pile.py's jitter) and their random k


@pytest.mark.parametrize('style', ['one', 'k'])
def test_a_pile_falls_asleep_and_stays_asleep_across_dropped_inputs(style: str) -> None:
    steady = [_asleep_after('k', seed, periods=1)[0] for seed in SEEDS]   # printed only
    dropped = [_asleep_after(style, seed) for seed in SEEDS]
    times = [elapsed for elapsed, _ in dropped]
    print(f'{style}: asleep after {np.round(times, 2)} s (every period answered: '
          f'{np.round(steady, 2)} s)')
    assert max(times) < 8.0
    sim = dropped[0][1]
    dynamic = sim.world.dynamic
    held = sim.state.copy()
    rng = np.random.default_rng(7)
    for _ in range(30):
        k = int(rng.integers(2, 5))
        current = sim.state
        for _ in range(k if style == 'k' else 1):
            current = sim.integrate(current)
        result = sim.world.step(sim.state, current, k * sim.dt)
        sim.state = result.states
        assert result.sleeping[dynamic].all()
    np.testing.assert_array_equal(sim.state.position, held.position)
    np.testing.assert_array_equal(sim.state.orientation, held.orientation)


@pytest.mark.parametrize('seed', [1, 2])
def test_a_body_answered_asleep_twice_in_a_row_has_not_moved(seed: int) -> None:
    """A pile of 200 cubes streamed at 30 Hz: a body answered asleep in two consecutive steps has
    the same pose in both (within 1e-9 m, at its bounding radius for a turn), and the pile
    still falls asleep within 5 s and stays so. An island woken by an awake body leaning on
    it is solved (it may sink) from the next step, and sleeps again only after
    ``time_to_sleep`` awake; before, its still time was kept and it fell asleep again in the
    step it was solved in, answered asleep both times (cubes 200: 5 steps, up to 1.4 mm)."""
    bodies, initial = make_pile(200, seed=seed, kind='cubes')
    sim = Simulation(bodies, initial, 30.0)
    dynamic = sim.world.dynamic
    reach = np.array([0.5 * np.linalg.norm(b.size) if b.shape == 'box' else
                      b.size[0] if b.shape == 'sphere' else 0.0 for b in bodies])
    was = np.zeros(len(bodies), bool)
    last = sim.state.copy()
    asleep_at, moved = None, []
    for k in range(int(6.0 * 30.0)):
        result = sim.step()
        now = result.sleeping & dynamic
        both = was & now
        shift = np.linalg.norm(result.states.position - last.position, axis=1)
        q, q0 = result.states.orientation, last.orientation   # the turn: 2 |dq| rad
        turn = 2.0 * np.minimum(np.linalg.norm(q - q0, axis=1),
                                np.linalg.norm(q + q0, axis=1)) * reach
        worst = np.maximum(shift, turn)[both].max(initial=0.0)
        if worst > 1e-9:
            moved.append((k, int((np.maximum(shift, turn)[both] > 1e-9).sum()), worst))
        if asleep_at is None and now[dynamic].all():
            asleep_at = (k + 1) / 30.0
        was, last = now, result.states.copy()
    print(f'cubes 200 (seed {seed}) at 30 Hz: asleep after {asleep_at} s; answered asleep '
          f'twice and moved (step, bodies, m): {moved[:5]}')
    assert not moved
    assert asleep_at is not None and asleep_at <= 5.0
    assert was[dynamic].all()
