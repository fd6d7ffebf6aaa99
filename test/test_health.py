"""The /diagnostics verdict over a recent window (collres_ros/ros/health.py)."""

from __future__ import annotations

from collections import Counter

from collres_ros.ros.health import ERROR, OK, STALE, WARN, Health


class Run:
    """A node's totals, reported once a second into a Health."""

    def __init__(self):
        self.health = Health()
        self.totals = Counter()
        self.now = 100.0

    def period(self, steps=10, refused=None, lost=0, served=None, inputs=None, **status):
        self.now += 1.0
        self.totals['steps'] += steps
        self.totals['inputs'] += steps if inputs is None else inputs
        self.totals['served'] += 2 * steps if served is None else served
        self.totals['lost'] += lost
        self.totals.update(refused or {})
        self.health.update(self.now, self.totals, 1.0)
        s = self.health.status(self.now, stale_after_s=1.0, **status)
        print(s.level, s.message)
        return s


def test_one_refused_input_warns_then_the_level_returns_to_ok():
    run = Run()
    assert run.period().level == OK
    assert run.period(refused={'non_finite': 1}).level == WARN
    levels = [run.period().level for _ in range(6)]
    assert levels == [WARN] * 4 + [OK, OK]          # a window of 5 reports
    assert run.totals['non_finite'] == 1            # the total stays


def test_fresh_starts_are_notices_not_faults():
    run = Run()
    s = run.period(refused={'time_backwards': 2})
    assert s.level == OK and 'fresh starts: time_backwards 2' in s.message


def test_losses_warn_and_are_named():
    s = Run().period(lost=12)
    assert s.level == WARN and 'lost before taken: 12' in s.message


def test_rate_below_min_rate_warns_and_no_step_is_an_error():
    run = Run()
    assert run.period(steps=10, min_rate=5.0).level == OK
    run = Run()
    assert run.period(steps=2, min_rate=5.0).level == WARN
    run = Run()
    s = run.period(steps=0, inputs=0, min_rate=5.0)
    assert s.level == ERROR and 'min_rate 5 Hz' in s.message


def test_no_input_is_stale_and_every_input_refused_is_an_error():
    run = Run()
    s = run.period(steps=0, inputs=0)
    assert s.level == STALE and 'no input yet' in s.message
    run = Run()
    run.period()
    run.period(steps=0, inputs=0)
    s = run.period(steps=0, inputs=0)
    assert s.level == STALE and 'no input for 2.0 s' in s.message
    s = Run().period(steps=5, served=0, refused={'wrong_frame': 10})
    assert s.level == ERROR and 'every input was refused' in s.message
    s = Run().period(refused={'non_finite_result': 1})
    assert s.level == ERROR


def test_unpaired_inputs_warn_with_the_reason():
    s = Run().period(steps=0, inputs=20, unpaired='poses without twists for: ball')
    assert s.level == WARN and 'poses without twists for: ball' in s.message


def test_a_sustained_stream_of_time_jumps_warns_naming_the_cause():
    run = Run()
    # two publishers on one topic, stamps near 1000 s and near 5 s, interleaved at 100 Hz:
    # every step is a fresh start (no sweep, no warm start: contact physics off)
    for _ in range(3):
        s = run.period(steps=100, refused={'time_backwards': 100, 'large_gap': 100})
    assert s.level == WARN and 'more than one clock' in s.message
    assert 'time jumps: 600 fresh starts in 300 steps' in s.message
    levels = [run.period(steps=100).level for _ in range(5)]
    assert levels[-1] == OK                          # over once the window has moved on
    calm = Run().period(steps=100, refused={'time_backwards': 2})   # a source restart
    assert calm.level == OK
