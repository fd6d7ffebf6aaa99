"""Lost inputs counted from publication sequence numbers (collres_ros/ros/losses.py)."""

from __future__ import annotations

import random

from hypothesis import given, settings, strategies as st

from collres_ros.ros.losses import LossCounter


def info(number):
    return {'publication_sequence_number': number, 'reception_sequence_number': None}


def test_gaps_between_numbers_are_the_lost_messages():
    counter = LossCounter()
    taken = [1, 2, 3, 10, 11, 2000]
    assert [counter.count('body_states', info(n)) for n in taken] == [0, 0, 0, 6, 0, 1988]
    assert counter.total_lost == 1994 and counter.received['body_states'] == 6


def test_a_restarted_publisher_starts_a_new_stream_without_loss():
    counter = LossCounter()
    for n in (1, 2, 3, 1, 2, 5):
        counter.count('t', info(n))
    assert counter.total_lost == 2


def test_no_number_counts_nothing():
    counter = LossCounter()
    counter.count('t', None)
    counter.count('t', {'publication_sequence_number': None})
    assert counter.total_lost == 0 and counter.unnumbered == 2


@settings(max_examples=200, deadline=None)
@given(st.integers(1, 3), st.integers(1, 300), st.floats(0.0, 0.95), st.randoms())
def test_interleaved_publishers_keep_the_total_exact(publishers, sent, loss, rnd):
    """Several publishers on one topic, each losing some messages: the total lost is exact
    when the survivors of the publishers arrive in publication order per publisher."""
    streams = []
    for _ in range(publishers):
        kept = [n for n in range(1, sent + 1) if n in (1, sent) or rnd.random() >= loss]
        streams.append(kept)
    lost = publishers * sent - sum(len(s) for s in streams)
    # interleave by a common clock: publisher p publishes number n at time n + p / 10
    merged = sorted(((n + p / 10.0, n) for p, s in enumerate(streams) for n in s))
    counter = LossCounter()
    for _, n in merged:
        counter.count('t', info(n))
    assert counter.total_lost == lost


def test_a_random_burst_is_counted_exactly():
    rnd = random.Random(7)
    kept = [1] + sorted(rnd.sample(range(2, 10_000), 500)) + [10_000]
    counter = LossCounter()
    for n in kept:
        counter.count('t', info(n))
    assert counter.total_lost == 10_000 - len(kept)


def test_several_publishers_never_make_a_phantom_loss():
    """Two publishers at 100 and 50 Hz, nothing dropped: the interleaved numbers look like
    gaps (11,175 phantom losses of 450 messages before); with the publisher count given,
    nothing is inferred, and counting resumes exactly once one publisher is left."""
    counter = LossCounter()
    fast = slow = 0
    for k in range(300):
        fast += 1
        assert counter.count('body_states', info(fast), publishers=2) == 0
        if k % 2:
            slow += 1
            assert counter.count('body_states', info(slow), publishers=2) == 0
    assert counter.total_lost == 0 and counter.uncounted['body_states'] == 450
    for n in (fast + 1, fast + 2, fast + 5):   # the slow one gone: exact again
        counter.count('body_states', info(n), publishers=1)
    assert counter.total_lost == 2
