"""Per-body stamp synchronisation (collres_ros/ros/sync.py)."""

from __future__ import annotations

from collres_ros.ros.sync import StampSync

MS = 1_000_000


def test_exact_sync_steps_when_every_dynamic_body_has_pose_and_twist():
    sync = StampSync(['a', 'b'], ['floor'])
    assert sync.add('a', 'pose', 10 * MS, 'pa') == []
    assert sync.add('a', 'twist', 10 * MS, 'ta') == []
    assert sync.add('b', 'pose', 10 * MS, 'pb') == []
    assert sync.add('floor', 'pose', 10 * MS, 'pf') == []
    done = sync.add('b', 'twist', 10 * MS, 'tb')
    assert [g.stamp_ns for g in done] == [10 * MS]
    assert done[0].parts == {'a': {'pose': 'pa', 'twist': 'ta'},
                             'b': {'pose': 'pb', 'twist': 'tb'}, 'floor': {'pose': 'pf'}}
    assert sync.pending == [] and sync.dropped == 0


def test_older_incomplete_stamps_are_dropped_and_counted():
    sync = StampSync(['a'])
    sync.add('a', 'pose', 10 * MS, 1)
    sync.add('a', 'pose', 20 * MS, 2)
    done = sync.add('a', 'twist', 20 * MS, 3)
    assert [g.stamp_ns for g in done] == [20 * MS] and sync.dropped == 1


def test_slop_groups_near_stamps():
    exact = StampSync(['a'], slop_ns=0)
    exact.add('a', 'pose', 10 * MS, 1)
    assert exact.add('a', 'twist', 10 * MS + 1, 2) == []
    loose = StampSync(['a'], slop_ns=MS)
    loose.add('a', 'pose', 10 * MS, 1)
    done = loose.add('a', 'twist', 10 * MS + MS // 2, 2)
    assert [g.stamp_ns for g in done] == [10 * MS]


def test_a_silent_body_goes_stale_and_the_others_are_served():
    sync = StampSync(['a', 'b'], stale_timeout_ns=100 * MS)
    for k in range(5):
        sync.add('b', 'pose', k * 10 * MS, 0)
        sync.add('b', 'twist', k * 10 * MS, 0)
    sync.add('a', 'pose', 0, 0)
    assert sync.add('a', 'twist', 0, 0) != []     # stamp 0 completes
    done = []
    for k in range(5, 20):
        sync.add('b', 'pose', k * 10 * MS, 0)
        done += sync.add('b', 'twist', k * 10 * MS, 0)
    assert sync.stale() == ['a']
    assert done and done[-1].stamp_ns == 190 * MS
    assert 'a' not in done[-1].parts


def test_a_stale_body_that_speaks_again_is_required_again():
    """Which bodies a step needs is kept between messages (a pass over every body per
    message made 100 bodies' per-body steps quadratic): it follows a body going stale and
    coming back, without a newer stamp in between."""
    sync = StampSync(['a', 'b'], stale_timeout_ns=100 * MS)
    for k in range(0, 20):
        sync.add('b', 'pose', k * 10 * MS, 0)
        done = sync.add('b', 'twist', k * 10 * MS, 0)
    assert sync.stale() == ['a'] and [g.stamp_ns for g in done] == [190 * MS]
    assert sync.add('a', 'pose', 200 * MS, 1) == []      # a is back: stamp 200 needs it
    assert sync.add('b', 'pose', 200 * MS, 2) == []
    assert sync.add('b', 'twist', 200 * MS, 3) == []     # not complete without a's twist
    done = sync.add('a', 'twist', 200 * MS, 4)
    assert [g.stamp_ns for g in done] == [200 * MS] and set(done[0].parts) == {'a', 'b'}


# --- clock jumps, stray stamps, slop, unpaired inputs ------------------------------------

S, DT = 10**9, 10 * MS


def _feed(sync, names, stamp, skip=()):
    done = []
    for name in names:
        for kind in ('pose', 'twist'):
            if (name, kind) not in skip and name not in skip:
                done += sync.add(name, kind, stamp, (name, kind, stamp))
    return done


def test_a_clock_jump_backwards_resets_the_sync_once_and_stepping_goes_on():
    sync = StampSync(['ball', 'box'], stale_timeout_ns=200 * MS)
    for k in range(50):
        _feed(sync, ('ball', 'box'), 1000 * S + k * DT)
    assert sync.take_jump() is None
    steps = []
    for k in range(1, 200):      # a new run from t = 0.01 s; the box goes silent after k = 10
        steps += _feed(sync, ('ball', 'box'), k * DT, skip=('box',) if k > 10 else ())
    stamps = [g.stamp_ns for g in steps]
    print('steps after the restart', len(stamps), 'stale', sync.stale(), 'jumps',
          sync.time_jumps)
    assert stamps[:10] == [k * DT for k in range(1, 11)]   # nothing of the new run is lost
    assert stamps[-1] == 199 * DT and len(stamps) == 199    # the ball goes on alone
    assert sync.stale() == ['box']
    assert sync.time_jumps == 1
    jump = sync.take_jump()
    assert jump is not None and jump.after_ns == DT and jump.before_ns == 1000 * S + 49 * DT
    assert 'backwards' in jump.text() and sync.take_jump() is None   # reported once


def test_a_single_far_future_stamp_is_refused_and_moves_no_clock():
    sync = StampSync(['ball', 'box'], stale_timeout_ns=200 * MS)
    T = 1000 * S
    steps = []
    for k in range(60):
        for name in ('ball', 'box'):
            stamp = T + 10**15 if (name == 'box' and k == 20) else T + k * DT
            for kind in ('pose', 'twist'):
                steps += sync.add(name, kind, stamp, None)
    print('stale', sync.stale(), 'refused', dict(sync.refused), 'steps', len(steps))
    assert sync.stale() == []
    assert sync.refused['future_stamp'] == 2 and sync.time_jumps == 0
    assert [g.stamp_ns for g in steps] == [T + k * DT for k in range(60) if k != 20]


def test_a_forward_jump_confirmed_by_the_next_message_is_taken():
    sync = StampSync(['ball'], stale_timeout_ns=200 * MS)
    steps = []
    for k in range(10):
        steps += _feed(sync, ('ball',), k * DT)
    for k in range(10):          # the source skipped an hour
        steps += _feed(sync, ('ball',), 3600 * S + k * DT)
    assert [g.stamp_ns for g in steps][-10:] == [3600 * S + k * DT for k in range(10)]
    assert sync.time_jumps == 1 and not sync.refused


def test_a_part_never_replaces_a_queued_part_of_another_stamp():
    T = 1000 * S
    sync = StampSync(['ball', 'box'], slop_ns=DT)
    out = []
    for k in range(6):
        order = [('ball', 'pose', k), ('box', 'pose', k), ('box', 'twist', k)]
        if k:
            order.append(('ball', 'twist', k - 1))     # the ball's twist lags one step
        for name, kind, kk in order:
            for g in sync.add(name, kind, T + kk * DT, kk):
                out.append(((g.stamp_ns - T) // DT, {m: dict(p) for m, p in g.parts.items()}))
    print(out)
    assert [s for s, _ in out] == [0, 1, 2, 3, 4]
    for stamp, parts in out:      # every part of a step is of that step
        assert all(v == stamp for p in parts.values() for v in p.values()), (stamp, parts)


def test_a_slop_of_half_the_period_or_more_is_reported():
    sync = StampSync(['ball'], slop_ns=5 * MS)
    for k in range(10):
        _feed(sync, ('ball',), k * DT)
    problem = sync.slop_problem()
    print(problem)
    assert problem and 'sync_slop 0.005 s' in problem and '0.01 s' in problem
    sync.slop_ns = 4 * MS
    assert sync.slop_problem() is None
    assert StampSync(['ball']).slop_problem() is None


def test_inputs_that_never_pair_say_why():
    poses = StampSync(['ball', 'box'])
    for k in range(5):
        for name in ('ball', 'box'):
            poses.add(name, 'pose', k * DT, None)
    assert poses.unpaired() == 'poses without twists for: ball, box'
    twists = StampSync(['ball'])
    twists.add('ball', 'twist', DT, None)
    assert twists.unpaired() == 'twists without poses for: ball'
    apart = StampSync(['ball'])
    for k in range(5):
        apart.add('ball', 'pose', k * DT, None)
        apart.add('ball', 'twist', k * DT + 1000, None)
    print(apart.unpaired())
    assert apart.unpaired().startswith('pose and twist stamps never match for: ball (1 us')
    assert StampSync(['ball']).unpaired() == ''


def test_a_gap_in_one_body_stream_does_not_stall_the_others():
    """Messages lost upstream leave a gap longer than the stale timeout in the ball's stamps.

    The box went silent before the gap: after it the ball must be served alone at once
    (the box is stale by its own last stamp), not held until the box is heard again.
    """
    sync = StampSync(['ball', 'box'], ['floor'], stale_timeout_ns=200 * MS)
    steps = []
    for k in range(40):
        names = ('ball', 'box') if k < 2 else ('ball',)
        if 3 <= k < 25:
            continue                   # the ball's messages 3..24 were lost
        steps += _feed(sync, names, k * DT)
    served = [g.stamp_ns // DT for g in steps]
    print('served', served)
    assert served[-15:] == list(range(25, 40))
    assert sync.stale() == ['box']


def test_a_synchronised_step_lists_its_bodies_in_the_scene_order_whatever_came_first():
    """The answer of a per-body step (``body_states/corrected``) lists the scene's bodies in
    the scene's order, then any the scene does not know (refused by the resolver), as their
    parts came, however the parts of this step were interleaved on the way."""
    from collres_ros.ros.codec import Stamped
    from collres_ros.ros.messages import batch_from_group

    order = ('floor', 'a', 'b', 'c')
    sync = StampSync(['a', 'b', 'c'], ['floor'])
    arrivals = [('c', 'twist'), ('stray', 'pose'), ('b', 'pose'), ('floor', 'pose'),
                ('a', 'twist'), ('stray', 'twist'), ('c', 'pose'), ('b', 'twist'),
                ('a', 'pose')]
    done = []
    for name, kind in arrivals:
        part = Stamped(10 * MS, 'world', (0.0,) * (7 if kind == 'pose' else 6))
        done += sync.add(name, kind, 10 * MS, part)
    assert len(done) == 1
    batch = batch_from_group(done[0].parts, frozenset(['a', 'b', 'c', 'stray']), order)
    assert list(batch.names) == ['floor', 'a', 'b', 'c', 'stray']
