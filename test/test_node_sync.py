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
