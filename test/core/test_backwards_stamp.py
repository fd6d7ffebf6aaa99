"""An input whose stamp goes back (behind the body's last resolved stamp) is refused,
counted ``time_backwards``, and changes nothing: the next good input is answered bit for
bit as if the refused one never came.

On 0cd02dd the input was used as a fresh start (previous = current, warm start and sleep
forgotten, a 1 ms step): the 100-body pile asleep at 30 Hz given one stamp 5 ms or 1 ns
behind restarted cold, its bodies moved again (up to 0.0295 m/s) and it was still awake
1 s later; a box landing at 240 Hz given one around touch-down gained up to 36.6 mJ (5 ms behind)
or 5.7 mJ (1 ns) of kinetic and potential energy in the step after, and ended up to
1.09 mm off the path it takes without it. A second input behind the last resolved stamp,
later than the refused one, is a new run of the source (a simulator restarted, a bag
played again): it starts fresh. A body behind in part of a batch is refused the same way,
the batch answered as without it.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

from collres_ros.core.config import SolverSettings
from collres_ros.core.pipeline import Resolver
from collres_ros.core.types import BodySpec, BodyStates, InputBatch

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / 'bench'))
from pile import integrate, make_pile  # noqa: E402

MS = 10**6


def _values(states: BodyStates) -> np.ndarray:
    return np.hstack([states.position, states.orientation, states.linear, states.angular])


def _energy(box: np.ndarray) -> float:
    """Kinetic and potential energy (J) of the 1 kg, 0.2 m box of state row ``box``."""
    inertia = 0.2 ** 2 / 6
    return float(0.5 * (box[7:10] @ box[7:10] + inertia * box[10:13] @ box[10:13])
                 + 9.81 * box[2])


def _twin_runs(bodies, state, rate, steps, glitch_at, behind_ns, sleeping=True):
    """Two resolvers driven as a source drives them (the answer integrated one period),
    one also given, after step ``glitch_at``, the last input again stamped ``behind_ns``
    behind: (refused step, the twin answers from step ``glitch_at`` on, pair by pair,
    the resolvers)."""
    moving = np.flatnonzero([not b.static for b in bodies])
    names = [bodies[i].name for i in moving]
    runs = [Resolver(bodies, SolverSettings(sleeping=sleeping)) for _ in range(2)]
    answer = BodyStates(state.position[moving], state.orientation[moving],
                        state.linear[moving], state.angular[moving])
    stamp, refused, after = 10**12, None, []
    period = int(round(1e9 / rate))
    for k in range(steps):
        stamp += period
        batch = InputBatch(names, _values(integrate(answer, np.ones(len(names), bool),
                                                    1.0 / rate)), 'world', 'world')
        clean, glitched = (r.resolve(stamp, batch) for r in runs)
        if k >= glitch_at:
            after.append((clean, glitched))
        if k == glitch_at:
            refused = runs[1].resolve(stamp - behind_ns, batch)
        answer = clean.states
    return refused, after, runs


@pytest.mark.parametrize('behind_ns', [5 * MS, 1])
def test_an_asleep_pile_given_a_stamp_behind_answers_as_if_it_never_came(behind_ns):
    bodies, state = make_pile(100, seed=1, kind='mixed')
    refused, after, runs = _twin_runs(bodies, state, 30.0, 150, 120, behind_ns)
    assert after[0][0].sleeping.all()   # asleep before the glitch (settles in ~3.7 s)
    fastest = max(float(np.linalg.norm(g.states.linear, axis=1).max()) for _, g in after)
    print(f'fastest body after the glitch {fastest:.3g} m/s')
    for clean, glitched in after:
        np.testing.assert_array_equal(glitched.values, clean.values)
        np.testing.assert_array_equal(glitched.sleeping, clean.sleeping)
    assert fastest == 0.0
    assert {r.reason for r in refused.rejected} == {'time_backwards'}
    assert refused.names == [] and refused.report.contacts.count == 0
    assert runs[1].totals['time_backwards'] == len(after[0][0].names)


@pytest.mark.parametrize('behind_ns', [5 * MS, 1])
def test_a_landing_box_given_a_stamp_behind_gains_no_energy_and_lands_as_without_it(
        behind_ns):
    """A box dropped 0.1 m onto a floor at 240 Hz; the input behind comes one step
    before touch-down, at touch-down and while it settles."""
    bodies = [BodySpec('floor', 'plane', (0.0, 0.0, 1.0, 0.0), static=True),
              BodySpec('box', 'box', (0.2, 0.2, 0.2), mass=1.0, restitution=0.0)]
    state = BodyStates.zeros(2)
    state.position[1] = (0.0, 0.0, 0.2)
    state.orientation[:, 3] = 1.0
    runs = {glitch_at: _twin_runs(bodies, state, 240.0, 60, glitch_at, behind_ns,
                                  sleeping=False) for glitch_at in (32, 33, 34, 40)}
    for glitch_at, (_, after, _) in runs.items():   # touch-down in step 33
        gained = _energy(after[1][1].values[0]) - _energy(after[0][0].values[0])
        print(f'glitch after step {glitch_at}: the step after gains {gained * 1e3:.3g} mJ')
        assert gained <= 1e-9
    for refused, after, _ in runs.values():
        for clean, glitched in after:
            np.testing.assert_array_equal(glitched.values, clean.values)
            np.testing.assert_array_equal(glitched.report.normal_impulse,
                                          clean.report.normal_impulse)
        assert [r.reason for r in refused.rejected] == ['time_backwards']


def test_a_source_restarted_behind_starts_fresh_from_its_second_input():
    bodies, state = make_pile(8, seed=1, kind='mixed')
    refused, after, runs = _twin_runs(bodies, state, 100.0, 20, 10, 0)
    names = refused.body_names[5:]
    restarted = runs[1]
    first = restarted.resolve(10**9, InputBatch(names, _values(BodyStates(
        *(a[5:] for a in (state.position, state.orientation, state.linear,
                          state.angular)))), 'world', 'world'))
    assert {r.reason for r in first.rejected} == {'time_backwards'} and first.names == []
    second = restarted.resolve(10**9 + 10 * MS, InputBatch(names, _values(BodyStates(
        *(a[5:] for a in (state.position, state.orientation, state.linear,
                          state.angular)))), 'world', 'world'))
    assert {r.reason for r in second.resets} == {'time_backwards'}
    assert second.names == list(names) and not second.rejected
    third = restarted.resolve(10**9 + 20 * MS, InputBatch(names, _values(second.states),
                                                          'world', 'world'))
    assert not third.resets and not third.rejected and third.dt == pytest.approx(0.01)


@pytest.mark.parametrize('ahead_ns', [5 * MS, 1])
def test_a_body_behind_in_part_of_a_batch_is_refused_as_if_absent_and_the_pile_sleeps_on(
        ahead_ns):
    """The 100-body pile asleep at 30 Hz; one body's input comes alone, stamped
    ``ahead_ns`` after the step's stamp, then the whole batch of that step: that body is
    behind in it, the 99 others are not. It is refused there (``time_backwards``, not
    answered) and the batch is answered bit for bit as the batch without it, then and on
    every later step; the pile stays asleep, every answer as without the glitch. On
    0cd02dd the body's input behind was used as a fresh start: the pile woke (up to
    0.164 m/s) and was still awake 1 s later."""
    bodies, state = make_pile(100, seed=1, kind='mixed')
    moving = np.flatnonzero([not b.static for b in bodies])
    names = [bodies[i].name for i in moving]
    clean, glitched, absent = (Resolver(bodies, SolverSettings(sleeping=True))
                               for _ in range(3))
    answer = BodyStates(state.position[moving], state.orientation[moving],
                        state.linear[moving], state.angular[moving])
    stamp, period, glitch_at, j = 10**12, int(round(1e9 / 30.0)), 120, 5
    others = [k for k in range(len(names)) if k != j]
    fastest = 0.0
    for k in range(glitch_at + 31):
        stamp += period
        values = _values(integrate(answer, np.ones(len(names), bool), 1.0 / 30.0))
        batch = InputBatch(names, values, 'world', 'world')
        expected = clean.resolve(stamp, batch)
        if k == glitch_at:
            assert expected.sleeping.all()   # asleep before the glitch (settles in ~3.7 s)
            alone = InputBatch([names[j]], values[j:j + 1], 'world', 'world')
            for run in (glitched, absent):
                run.resolve(stamp + ahead_ns, alone)
            got = glitched.resolve(stamp, batch)
            without = absent.resolve(stamp, InputBatch([names[k] for k in others],
                                                       values[others], 'world', 'world'))
            assert [(r.body, r.reason) for r in got.rejected] == [(names[j], 'time_backwards')]
            assert got.names == without.names and names[j] not in got.names
        else:
            got, without = (run.resolve(stamp, batch) for run in (glitched, absent))
        np.testing.assert_array_equal(got.values, without.values)
        np.testing.assert_array_equal(got.sleeping, without.sleeping)
        if k > glitch_at:
            fastest = max(fastest, float(np.linalg.norm(got.states.linear, axis=1).max()))
            np.testing.assert_array_equal(got.values, expected.values)
            assert got.sleeping.all()
        answer = expected.states
    print(f'fastest body after the glitch {fastest:.3g} m/s')
    assert fastest == 0.0
