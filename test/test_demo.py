"""End to end over real DDS: collres_node and collres_sim as processes, recorded by the demo.

Asserts: the ball's apex heights within 3 % of h0 e^2n, the
resting box within 1 mm, every input step answered by exactly one corrected
output, no dropped step, and that the bag recorded live, replayed offline
through the same core, gives the same corrected states within 1e-9.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

pytest.importorskip('rclpy')

pytestmark = pytest.mark.slow


@pytest.fixture(scope='module')
def demo(tmp_path_factory: pytest.TempPathFactory):
    from conftest import next_domain_id
    from collres_ros.demo import run_demo
    out = tmp_path_factory.mktemp('demo')
    result = run_demo(out, domain_id=next_domain_id(), progress=False, timeout=120.0)
    from collres_ros.demo import summary_lines
    print('\n'.join(summary_lines(result)))
    return result


def test_every_input_step_got_exactly_one_output(demo) -> None:
    report = demo.report
    assert demo.expected_steps > 100
    assert report.steps_in == demo.expected_steps
    assert report.steps_out == report.steps_in
    assert report.unanswered == 0 and report.duplicated == 0
    assert demo.node_exit == 0 and demo.sim_exit == 0
    assert demo.ok


def test_ball_apexes_follow_the_e2_law_within_3_percent(demo) -> None:
    bounce = demo.report.bounce
    assert bounce is not None, 'no ball bounced'
    assert len(bounce.measured) >= 2, f'only {len(bounce.measured)} apexes'
    for n, (m, e) in enumerate(zip(bounce.measured, bounce.expected), 1):
        print(f'apex {n}: {m:.4f} m vs {e:.4f} m ({100 * (m / e - 1):+.2f} %)')
        assert m == pytest.approx(e, rel=0.03)
    assert demo.report.contacts.get('IMPACT', 0) >= len(bounce.measured)


def test_resting_box_stays_within_1_mm(demo) -> None:
    drift = demo.report.resting_drift
    assert drift, 'the default scene has no box at rest'
    for name, moved in drift.items():
        print(f'{name}: {1000 * moved:.4f} mm')
        assert moved < 1e-3
    assert any(line.endswith('(nothing should move it)') for line in demo.report.lines())
    assert demo.report.contacts.get('RESTING', 0) + demo.report.contacts.get('STICKING', 0) > 0


def test_plot_and_bag_are_written(demo) -> None:
    from collres_ros.ros.bag import BagReader
    assert demo.plot.is_file() and demo.plot.read_bytes()[:8] == b'\x89PNG\r\n\x1a\n'
    with BagReader(demo.bag) as reader:
        for topic in ('/body_states', '/body_states/corrected', '/contacts',
                      '/contact_markers', '/diagnostics'):
            assert topic in reader.topics


def _largest_replay_difference(bag: Path, out: Path) -> float:
    """Replay a live bag offline; the largest |live - offline| over all corrected states."""
    from collres_ros.ros.bag import read_messages
    from collres_ros.ros.offline import replay
    from collres_ros.ros.resources import config_path
    replay(bag, out, config_path('collres.yaml'), topics=('body_states/corrected',))

    def by_stamp(path: Path) -> dict:
        out = {}
        for m in read_messages(path, ['/body_states/corrected']):
            stamp = m.msg.header.stamp.sec * 10**9 + m.msg.header.stamp.nanosec
            out[stamp] = {b.name: np.array([
                b.pose.position.x, b.pose.position.y, b.pose.position.z,
                b.pose.orientation.x, b.pose.orientation.y, b.pose.orientation.z,
                b.pose.orientation.w, b.twist.linear.x, b.twist.linear.y, b.twist.linear.z,
                b.twist.angular.x, b.twist.angular.y, b.twist.angular.z])
                for b in m.msg.bodies}
        return out

    live, offline = by_stamp(bag), by_stamp(out)
    assert len(live) > 0 and sorted(live) == sorted(offline)
    worst = 0.0
    for stamp, bodies in live.items():
        assert sorted(bodies) == sorted(offline[stamp])
        for name, values in bodies.items():
            worst = max(worst, float(np.max(np.abs(values - offline[stamp][name]))))
    print(f'largest live vs offline difference: {worst:.3e}')
    return worst


def test_live_bag_replayed_offline_gives_the_live_corrected_states(demo, tmp_path: Path) -> None:
    assert _largest_replay_difference(demo.bag, tmp_path / 'replayed') <= 1e-9


def test_per_body_live_run_replays_to_the_same_states(tmp_path: Path) -> None:
    """The sim on per-body topics over DDS; replay groups them by stamp like the node."""
    from conftest import next_domain_id
    from collres_ros.ros.bag import BagReader
    from collres_ros.demo import run_demo
    result = run_demo(tmp_path / 'demo', duration=1.0, domain_id=next_domain_id(),
                      progress=False, per_body=True)
    assert result.ok, result.report.lines()
    with BagReader(result.bag) as reader:
        assert '/body_states' not in reader.topics
        assert reader.topic_count('/bodies/ball/pose') == result.expected_steps
    assert _largest_replay_difference(result.bag, tmp_path / 'replayed') <= 1e-9


def test_demo_bad_params_is_one_error_line(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    from collres_ros.demo import main
    assert main(['--params', str(tmp_path / 'missing.yaml'), '--out', str(tmp_path)]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith('error: ') and 'missing.yaml' in err[0]


def test_the_live_bag_carries_the_offered_qos_and_the_params(demo) -> None:
    """The recorder writes what the publishers offered, and the scene, to metadata.yaml."""
    import yaml

    from collres_ros import __version__
    from collres_ros.ros import params
    from collres_ros.ros.resources import config_path
    info = yaml.safe_load((demo.bag / 'metadata.yaml').read_text())
    info = info['rosbag2_bagfile_information']
    found = {t['topic_metadata']['name']: t['topic_metadata']['offered_qos_profiles']
             for t in info['topics_with_message_count']}
    for topic in ('/body_states', '/body_states/corrected', '/contacts', '/diagnostics'):
        print(topic, found[topic])
        assert found[topic], f'{topic}: no offered_qos_profiles'
        assert {p['reliability'] for p in found[topic]} == {'reliable'}
        assert {p['durability'] for p in found[topic]} == {'volatile'}
    assert info['custom_data']['collres_ros.version'] == __version__
    path = demo.bag.parent / 'recorded_params.yaml'
    path.write_text(info['custom_data']['collres_ros.params'])
    assert params.load_scene(path).bodies == params.load_scene(config_path()).bodies
