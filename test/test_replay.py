"""collres_replay: error paths, determinism, batched vs per-body input, storages."""

from __future__ import annotations

from pathlib import Path

import pytest

pytest.importorskip('rclpy')

from collres_ros.ros.bag import BagReader, BagWriter, message_fields, read_messages  # noqa: E402
from collres_ros.replay import main  # noqa: E402
from collres_ros.ros.offline import replay, run_offline  # noqa: E402
from collres_ros.ros.simulation import load_sim_scene  # noqa: E402

SCENES = Path(__file__).resolve().parent.parent / 'config' / 'scenes'
BALL = SCENES / 'bouncing_ball.yaml'
# /diagnostics carries wall-clock timings (step time, rates): not deterministic by design
DETERMINISTIC = ('/body_states/corrected', '/contacts', '/contact_markers')


@pytest.fixture(scope='module')
def ball_bag(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """0.8 s of the bouncing ball (one impact) recorded offline: inputs only."""
    path = tmp_path_factory.mktemp('replay') / 'ball'
    run_offline(load_sim_scene(BALL, 0.8), path, topics=['body_states'])
    return path


def _fields(path: Path, topics: tuple[str, ...] = DETERMINISTIC) -> list:
    return [(m.topic, m.log_time, message_fields(m.msg)) for m in read_messages(path)
            if m.topic in topics]


def _error_line(capsys: pytest.CaptureFixture, code: int) -> str:
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 1
    assert len(err) == 1 and err[0].startswith('error: '), err
    assert 'Traceback' not in err[0]
    return err[0]


def test_replay_writes_every_output_topic_at_the_input_log_times(ball_bag: Path,
                                                                 tmp_path: Path) -> None:
    summary = replay(ball_bag, tmp_path / 'out', BALL)
    inputs = read_messages(ball_bag)
    with BagReader(tmp_path / 'out') as reader:
        topics = reader.topics
    for topic in ('/body_states/corrected', '/contacts', '/contact_markers', '/diagnostics'):
        assert topic in topics, topics
    corrected = [m for m in read_messages(tmp_path / 'out')
                 if m.topic == '/body_states/corrected']
    print(f'{summary.steps} steps, contacts {summary.contacts}')
    assert summary.steps == len(inputs) == len(corrected)
    assert [m.log_time for m in corrected] == [m.log_time for m in inputs]
    assert [message_fields(m.msg.header.stamp) for m in corrected] == \
        [message_fields(m.msg.header.stamp) for m in inputs]
    assert summary.contacts.get('IMPACT', 0) >= 1, 'the ball never hit the floor'


def test_replay_is_deterministic(ball_bag: Path, tmp_path: Path) -> None:
    replay(ball_bag, tmp_path / 'a', BALL)
    replay(ball_bag, tmp_path / 'b', BALL)
    first, second = _fields(tmp_path / 'a'), _fields(tmp_path / 'b')
    assert len(first) > 0
    assert first == second


def test_sqlite3_in_and_out_give_the_same_messages(ball_bag: Path, tmp_path: Path) -> None:
    with BagWriter(tmp_path / 'in_sqlite', 'sqlite3') as writer:
        for m in read_messages(ball_bag):
            writer.write(m.topic, m.log_time, m.msg)
    replay(tmp_path / 'in_sqlite', tmp_path / 'out_sqlite', BALL)
    replay(ball_bag, tmp_path / 'out_mcap', BALL, storage='mcap')
    with BagReader(tmp_path / 'out_sqlite') as reader:
        assert reader.storage == 'sqlite3'
    assert _fields(tmp_path / 'out_sqlite') == _fields(tmp_path / 'out_mcap')


def test_per_body_input_gives_the_same_corrected_states(ball_bag: Path, tmp_path: Path) -> None:
    from geometry_msgs.msg import PoseStamped, TwistStamped
    with BagWriter(tmp_path / 'per_body', 'mcap') as writer:
        for m in read_messages(ball_bag):
            for body in m.msg.bodies:
                writer.write(f'/bodies/{body.name}/pose', m.log_time,
                             PoseStamped(header=m.msg.header, pose=body.pose))
                writer.write(f'/bodies/{body.name}/twist', m.log_time,
                             TwistStamped(header=m.msg.header, twist=body.twist))
    summary = replay(tmp_path / 'per_body', tmp_path / 'out_per_body', BALL)
    replay(ball_bag, tmp_path / 'out_batched', BALL)
    topics = ('/body_states/corrected', '/contacts')
    per_body = _fields(tmp_path / 'out_per_body', topics)
    assert summary.steps == len(read_messages(ball_bag))
    assert [f[2] for f in per_body] == [f[2] for f in _fields(tmp_path / 'out_batched', topics)]
    with BagReader(tmp_path / 'out_per_body') as reader:
        assert '/bodies/ball/pose/corrected' in reader.topics
        assert '/bodies/ball/twist/corrected' in reader.topics


def test_missing_input_bag(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    line = _error_line(capsys, main([str(tmp_path / 'nope'), str(tmp_path / 'out'),
                                     '--params', str(BALL)]))
    assert 'not found' in line


def test_unknown_storage(ball_bag: Path, tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    line = _error_line(capsys, main([str(ball_bag), str(tmp_path / 'out'), '--params', str(BALL),
                                     '--storage', 'hdf5']))
    assert "unknown storage 'hdf5'" in line
    fake = tmp_path / 'fake_bag'
    fake.mkdir()
    (fake / 'metadata.yaml').write_text('rosbag2_bagfile_information:\n'
                                        '  storage_identifier: hdf5\n')
    line = _error_line(capsys, main([str(fake), str(tmp_path / 'out2'), '--params', str(BALL)]))
    assert "unknown storage 'hdf5'" in line


def test_missing_topics(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    from std_msgs.msg import String
    with BagWriter(tmp_path / 'other', 'mcap') as writer:
        writer.write('/chatter', 1, String(data='hello'))
    line = _error_line(capsys, main([str(tmp_path / 'other'), str(tmp_path / 'out'),
                                     '--params', str(BALL)]))
    assert 'no input topics' in line and '/chatter' in line


def test_bad_params(ball_bag: Path, tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    bad = tmp_path / 'bad.yaml'
    bad.write_text(BALL.read_text().replace('restitution: 0.8', 'restitution: 1.5'))
    line = _error_line(capsys, main([str(ball_bag), str(tmp_path / 'out'), '--params',
                                     str(bad)]))
    assert 'restitution' in line
    line = _error_line(capsys, main([str(ball_bag), str(tmp_path / 'out2'), '--params',
                                     str(tmp_path / 'missing.yaml')]))
    assert 'missing.yaml' in line


def test_output_exists(ball_bag: Path, capsys: pytest.CaptureFixture) -> None:
    line = _error_line(capsys, main([str(ball_bag), str(ball_bag), '--params', str(BALL)]))
    assert 'already exists' in line


def test_summary_on_stdout(ball_bag: Path, tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    assert main([str(ball_bag), str(tmp_path / 'out'), '--params', str(BALL)]) == 0
    out = capsys.readouterr()
    assert 'steps: ' in out.out and 'contacts: IMPACT' in out.out
    assert 'rejected inputs: ' in out.out
    assert '\r' not in out.err   # no progress line off a terminal (test_hygiene: on one)


def test_fast_decoder_equals_rclpy_deserialization() -> None:
    """Replay's CDR fast path gives exactly the BodyInputs of the rclpy path."""
    from rclpy.serialization import deserialize_message, serialize_message

    from collres_ros.ros import messages
    from collres_ros.msg import BodyState, BodyStateArray
    from collres_ros.ros.codec import decode_body_state_array
    msg = BodyStateArray()
    msg.header.frame_id = 'odd_frame'
    msg.header.stamp.sec, msg.header.stamp.nanosec = 12, 345
    for k, name in enumerate(['a', 'bb', 'ccc', 'dddd', 'eeeee', '', 'ünï']):
        body = BodyState(name=name)
        body.pose.position.x, body.pose.orientation.w = 0.1 * k, 1.0 - 1e-3 * k
        body.twist.angular.z = -float(k)
        msg.bodies.append(body)
    for m in (msg, BodyStateArray()):
        data = serialize_message(m)
        slow = deserialize_message(data, BodyStateArray)
        assert decode_body_state_array(data) == (
            messages.stamp_ns(slow.header.stamp), messages.inputs_from_array(slow))
