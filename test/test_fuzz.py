"""Property-based fuzzing (hypothesis) of every input edge: validation, the resolver,
StampSync, params files and bag messages.

Each property states what must hold for *any* input: no exception other than the
documented one, nothing non-finite out, every input accounted for once, one-line errors.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import replace
from pathlib import Path

import numpy as np
import yaml
from hypothesis import HealthCheck, given, settings, strategies as st

from collres_ros.core.pipeline import Resolver
from collres_ros.core.types import BodyInput, InputBatch
from collres_ros.core.validation import check_inputs
from collres_ros.ros import params
from collres_ros.ros.sync import StampSync

FUZZ = settings(max_examples=150, deadline=None,
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])
NAMES = ['floor', 'ball', 'box']
SCENE = params.scene_from_values({
    'bodies': NAMES, 'body.floor.shape': 'box', 'body.floor.size': [10.0, 10.0, 0.2],
    'body.floor.static': True, 'body.floor.position': [0.0, 0.0, -0.1],
    'body.ball.size': [0.1], 'body.ball.position': [0.0, 0.0, 0.5],
    'body.box.shape': 'box', 'body.box.size': [0.2, 0.2, 0.2],
    'body.box.position': [0.5, 0.0, 0.1]})

number = st.one_of(st.floats(allow_nan=True, allow_infinity=True),
                   st.floats(-2.0, 2.0), st.sampled_from([0.0, 1.0, -0.0, 1e308, -1e-320]))
near = st.floats(-1.0, 1.0)
name = st.one_of(st.sampled_from(NAMES), st.text(max_size=12))
frame = st.sampled_from(['world', '', 'map', 'ball', 'box'])


@st.composite
def body_input(draw, wild=True):
    value = number if wild else near
    q = draw(st.one_of(st.just((0.0, 0.0, 0.0, 1.0)), st.tuples(value, value, value, value)))
    return BodyInput(draw(name if wild else st.sampled_from(NAMES[1:])),
                     draw(st.tuples(value, value, value)), q,
                     draw(st.tuples(value, value, value)), draw(st.tuples(value, value, value)),
                     draw(frame if wild else st.just('world')),
                     draw(frame if wild else st.just('world')))


@FUZZ
@given(st.lists(body_input(), max_size=8))
def test_validation_accounts_for_every_input_and_passes_only_finite_unit_states(inputs):
    index_of = {n: i for i, n in enumerate(NAMES)}
    checked = check_inputs(inputs, index_of, 'world')
    assert len(checked.index) + len(checked.rejected) == len(inputs)
    for array in (checked.position, checked.orientation, checked.linear, checked.angular):
        assert np.isfinite(array).all()
    norms = np.linalg.norm(checked.orientation, axis=1)
    assert np.all(np.abs(norms - 1.0) < 1e-9)
    assert all(r.reason and '\n' not in r.detail for r in checked.rejected)


@st.composite
def accepted_input(draw, name):
    """A valid input of ``name``: a quaternion off unit length within the tolerance."""
    q = np.array(draw(st.tuples(near, near, near, near))) + [0.0, 0.0, 0.0, 2.0]
    q *= (1.0 + draw(st.floats(-5e-4, 5e-4))) / np.linalg.norm(q)
    vector = st.tuples(near, near, near)
    return BodyInput(name, draw(vector), tuple(q.tolist()), draw(vector), draw(vector),
                     'world', 'world')


@FUZZ
@given(accepted_input('ball'), accepted_input('box'), st.lists(body_input(), max_size=3))
def test_an_accepted_input_is_checked_alike_whatever_else_the_step_holds(ball, box, others):
    """A body's checked state does not depend on the other inputs of its step: a step of
    accepted inputs only (checked by whole-array tests) and the same inputs beside others,
    refused ones among them (checked one reason at a time), give the same bits for it."""
    index_of = {n: i for i, n in enumerate(NAMES)}
    alone = check_inputs(replace(InputBatch.of([ball, box]), frame_id='world',   # as decoded
                                 twist_frame_id='world'), index_of, 'world')
    mixed = check_inputs([ball, box] + others, index_of, 'world')
    assert not alone.rejected
    repeated = {b.name for b in others}
    for k, body in enumerate((ball, box)):
        if body.name in repeated:
            continue   # repeated in the mixed step: every copy is refused there
        j = list(mixed.index).index(index_of[body.name])
        for a, b in ((alone.position, mixed.position), (alone.orientation, mixed.orientation),
                     (alone.linear, mixed.linear), (alone.angular, mixed.angular)):
            assert a[k].tobytes() == b[j].tobytes()


@FUZZ
@given(st.lists(st.tuples(st.integers(-3, 40), st.lists(body_input(), max_size=4)),
                max_size=12))
def test_the_resolver_never_raises_warns_or_outputs_non_finite(steps):
    resolver = Resolver.for_scene(SCENE)
    with warnings.catch_warnings():
        warnings.simplefilter('error')      # an overflow warning would reach stderr
        for k, inputs in steps:
            out = resolver.resolve(10**9 + k * 10**7, inputs)
            for array in (out.states.position, out.states.orientation, out.states.linear,
                          out.states.angular):
                assert np.isfinite(array).all()
            assert len(out.names) == len(set(out.names))


@FUZZ
@given(st.lists(st.tuples(st.sampled_from(['a', 'b', 'floor']), st.sampled_from(['pose', 'twist']),
                          st.one_of(st.integers(0, 60), st.integers(0, 10**6))),
                max_size=120),
       st.sampled_from([0, 3, 10]))
def test_stamp_sync_groups_are_complete_and_never_mix_stamps(messages, slop):
    ms = 1_000_000
    sync = StampSync(['a', 'b'], ['floor'], slop_ns=slop * ms, stale_timeout_ns=200 * ms)
    previous = None
    jumps = 0
    for body, kind, stamp in messages:
        for group in sync.add(body, kind, stamp * ms, (body, kind, stamp * ms)):
            if sync.time_jumps != jumps:
                jumps, previous = sync.time_jumps, None
            if previous is not None:
                assert group.stamp_ns > previous
            previous = group.stamp_ns
            for part_body, parts in group.parts.items():
                for part_kind, msg in parts.items():
                    assert msg[0] == part_body and msg[1] == part_kind
                    assert abs(msg[2] - group.stamp_ns) <= slop * ms
            stale = set(sync.stale())
            assert all(len(group.parts.get(n, {})) == 2 for n in ('a', 'b') if n not in stale)
    assert sync.unpaired() is not None
    assert sum(sync.refused.values()) >= 0


yaml_value = st.recursive(
    st.one_of(st.none(), st.booleans(), st.integers(-10**20, 10**20), st.floats(),
              st.text(max_size=20)),
    lambda inner: st.one_of(st.lists(inner, max_size=5),
                            st.dictionaries(st.text(max_size=10), inner, max_size=5)),
    max_leaves=20)
known = st.sampled_from(['bodies', 'world_frame', 'body', 'solver', 'queue_depth',
                         'sync_slop', 'min_rate', 'rate_hz', 'gravity'])


@FUZZ
@given(st.dictionaries(st.one_of(known, st.text(max_size=10)), yaml_value, max_size=6),
       st.sampled_from(['/**', 'collres_node', 'other']))
def test_any_params_file_loads_or_fails_with_one_line(tmp_path_factory, values, section):
    path = Path(tmp_path_factory.mktemp('p')) / 'p.yaml'
    path.write_text(yaml.safe_dump({section: {'ros__parameters': values}}))
    try:
        scene = params.load_scene(path)
    except (ValueError, OSError) as error:
        text = str(error)
        assert text and '\n' not in text and len(text) < 2000, text
    else:
        assert scene.bodies


@FUZZ
@given(st.binary(max_size=400), st.integers(0, 399), st.binary(min_size=1, max_size=8))
def test_any_bytes_as_a_body_state_array_decode_or_are_refused(data, at, patch):
    from collres_ros.ros import codec as replay
    from collres_ros.msg import BodyState, BodyStateArray
    from rclpy.serialization import serialize_message
    good = bytearray(serialize_message(BodyStateArray(bodies=[BodyState(name='ball')])))
    good[at % len(good):at % len(good) + len(patch)] = patch
    for blob in (data, bytes(good)):
        try:
            decoded = replay.decode_body_state_array(blob)
        except (ValueError, UnicodeDecodeError, __import__('struct').error):
            continue
        if decoded is not None:
            stamp, inputs = decoded
            assert isinstance(stamp, int)
            assert all(isinstance(i.name, str) and len(i.position) == 3 for i in inputs)
            assert all(math.isfinite(c) or not math.isfinite(c) for i in inputs
                       for c in i.position)


# --- what the fuzzing found (each failed before its fix) ------------------------------------

def test_found_a_huge_quaternion_is_refused_without_an_overflow_warning():
    huge = BodyInput('ball', (0.0, 0.0, 0.0), (1e308, 1e308, 0.0, 0.0), (0.0, 0.0, 0.0),
                     (0.0, 0.0, 0.0), 'world', 'world')
    with warnings.catch_warnings():
        warnings.simplefilter('error')
        checked = check_inputs([huge], {'ball': 0}, 'world')
    assert [r.reason for r in checked.rejected] == ['non_unit_quaternion']


def test_found_a_name_cannot_forge_log_lines_nor_flood_them():
    ok = (0.0, 0.0, 0.0)
    forged = BodyInput('x\n[ERROR] [collres_node]: forged', ok, (0.0, 0.0, 0.0, 1.0), ok, ok,
                       'world', 'world')
    flood = BodyInput('u' * 10_000, ok, (0.0, 0.0, 0.0, 1.0), ok, ok, 'w' * 10_000, 'world')
    checked = check_inputs([forged, flood], {'ball': 0}, 'world')
    details = [r.detail for r in checked.rejected]
    print(details)
    assert all('\n' not in d and len(d) < 120 for d in details)
