"""Every input accounted for: collres_node over DDS, inputs sent vs resolved, refused, lost.

Starts the real ``collres_node`` as a child process in a private ROS_DOMAIN_ID and
publishes ``body_states`` from this process, then reads the node's own totals from
``/diagnostics`` once they stop changing and prints one table:

    sent = taken by the node + lost before it was taken (publication sequence gaps)
    taken = resolved steps + messages refused whole (e.g. oversized, bad stamp)

and the bodies refused by reason; ``unaccounted`` (the goal: 0) is what neither
explains. Three modes:

* ``soak``: the settled 100-body pile (``config/scenes/pile.yaml``) at ``--rate`` Hz
  for ``--duration`` s, the node's RSS sampled at start, middle and end;
* ``fuzz``: ``--count`` messages of 24 kinds (valid, NaN, Inf, zero and huge
  quaternions, unknown, duplicate and long names, wrong frames, stamps repeated,
  backwards, far ahead, negative, unnormalised, empty, oversized, ...) on the
  ball-and-box test scene, at ``--rate`` Hz (0: as fast as possible);
* ``burst``: ``--count`` valid steps of the test scene as fast as possible (above
  the node's throughput: the queue overflows and the losses must be counted).

Usage::

    .venv/bin/python bench/bench_accounting.py soak [--duration 600] [--rate 10]
    .venv/bin/python bench/bench_accounting.py fuzz [--count 10000] [--rate 0]
    .venv/bin/python bench/bench_accounting.py burst [--count 2000]
"""

from __future__ import annotations

import argparse
import math
import os
import random
import sys
import tempfile
import time
from pathlib import Path
from typing import Callable, Optional

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / 'test'))

from ros_harness import Peer, write_scene  # noqa: E402

from builtin_interfaces.msg import Time  # noqa: E402
from diagnostic_msgs.msg import DiagnosticArray  # noqa: E402

from collres_ros.msg import BodyState, BodyStateArray  # noqa: E402
from collres_ros.ros import processes  # noqa: E402

NS = 1_000_000_000
T0 = 1_000 * NS


def rss_mb(pid: int) -> float:
    """Resident set size of a process, MB (from /proc)."""
    for line in Path(f'/proc/{pid}/status').read_text().splitlines():
        if line.startswith('VmRSS:'):
            return int(line.split()[1]) / 1024.0
    return math.nan


def stamp(ns: int) -> Time:
    """Any ns (negative or unnormalised on purpose in the fuzz) as a Time."""
    sec, nanosec = divmod(ns, NS)
    return Time(sec=max(min(sec, 2**31 - 1), -2**31), nanosec=nanosec)


def body(name: str, x: float = 0.0, z: float = 0.5, q=(0.0, 0.0, 0.0, 1.0), vz: float = 0.0
         ) -> BodyState:
    b = BodyState(name=name)
    b.pose.position.x, b.pose.position.z = x, z
    o = b.pose.orientation
    o.x, o.y, o.z, o.w = q
    b.twist.linear.z = vz
    return b


def array(ns: int, bodies: list[BodyState], frame: str = 'world',
          sec: Optional[int] = None, nanosec: Optional[int] = None) -> BodyStateArray:
    msg = BodyStateArray(bodies=bodies)
    msg.header.frame_id = frame
    msg.header.stamp = stamp(ns)
    if sec is not None:
        msg.header.stamp.sec = sec
    if nanosec is not None:
        msg.header.stamp.nanosec = nanosec
    return msg


def fuzz_messages(count: int, seed: int = 10) -> list[tuple[str, BodyStateArray]]:
    """``count`` (kind, message) pairs of 24 kinds on the floor/ball/box scene, stamps
    advancing 10 ms per message (the hostile ones bend them on purpose)."""
    rng = random.Random(seed)
    nan, inf = math.nan, math.inf
    box = body('box', x=1.0, z=0.1)
    kinds: list[tuple[str, Callable[[int], BodyStateArray]]] = [
        ('valid', lambda t: array(t, [body('ball', z=rng.uniform(0.1, 1.0)), box])),
        ('nan_position', lambda t: array(t, [body('ball', z=nan), box])),
        ('inf_velocity', lambda t: array(t, [body('ball', vz=inf), box])),
        ('zero_quaternion', lambda t: array(t, [body('ball', q=(0.0, 0.0, 0.0, 0.0)), box])),
        ('non_unit_quaternion', lambda t: array(t, [body('ball', q=(0.0, 0.0, 0.0, 2.0)),
                                                    box])),
        ('huge_quaternion', lambda t: array(t, [body('ball', q=(1e308, 1e308, 0.0, 0.0)),
                                                box])),
        ('huge_position', lambda t: array(t, [body('ball', x=1e308), box])),
        ('huge_velocity', lambda t: array(t, [body('ball', vz=-1e300), box])),
        ('unknown_body', lambda t: array(t, [body('ghost'), body('ball'), box])),
        ('duplicate_body', lambda t: array(t, [body('ball'), body('ball', z=0.6), box])),
        ('long_name', lambda t: array(t, [body('u' * 10_000), body('ball'), box])),
        ('non_ascii_name', lambda t: array(t, [body('b\u00e4ll\n'), body('ball'), box])),
        ('wrong_frame', lambda t: array(t, [body('ball'), box], frame='map')),
        ('empty_frame', lambda t: array(t, [body('ball'), box], frame='')),
        ('empty', lambda t: array(t, [])),
        ('static_only', lambda t: array(t, [body('floor', z=-0.1)])),
        ('repeated_stamp', lambda t: array(t - 10_000_000, [body('ball'), box])),
        ('backwards', lambda t: array(t - 5 * NS, [body('ball'), box])),
        ('far_future', lambda t: array(t + 10**6 * NS, [body('ball'), box])),
        ('negative_stamp', lambda t: array(t, [body('ball'), box], sec=-5)),
        ('unnormalised_nanosec', lambda t: array(t, [body('ball'), box], nanosec=2 * NS)),
        ('subnormal', lambda t: array(t, [body('ball', x=5e-324, z=0.5), box])),
        ('many_unknown', lambda t: array(t, [body(f'u{j}') for j in range(1000)])),
        ('floor_and_ball', lambda t: array(t, [body('floor', z=-0.1), body('ball', z=0.09)])),
    ]
    out = []
    for k in range(count):
        kind, build = kinds[0] if k % 3 == 0 else kinds[rng.randrange(len(kinds))]
        out.append((kind, build(T0 + k * 10_000_000)))
    return out


def pile_messages(count: int) -> tuple[Path, list[BodyStateArray]]:
    """The 100-body pile settled offline (240 steps), then ``count`` steps of it at rest."""
    from collres_ros.core.pipeline import Resolver
    from collres_ros.core.types import BodyInput
    from collres_ros.ros.integrator import euler_step
    from collres_ros.ros.params import load_scene
    import numpy as np
    path = ROOT / 'config' / 'scenes' / 'pile.yaml'
    scene = load_scene(path)
    resolver = Resolver.for_scene(scene)
    states = scene.initial.copy()
    dynamic = np.array([not b.static for b in scene.bodies])
    dt = 1.0 / 60.0
    for k in range(240):
        states = euler_step(states, dynamic, np.array(scene.sim.gravity), dt)
        inputs = [BodyInput(b.name, tuple(states.position[i]), tuple(states.orientation[i]),
                            tuple(states.linear[i]), tuple(states.angular[i]), 'world',
                            'world') for i, b in enumerate(scene.bodies) if not b.static]
        out = resolver.resolve(int(k * dt * NS), inputs)
        for name in ('position', 'orientation', 'linear', 'angular'):
            getattr(states, name)[out.index] = getattr(out.states, name)
    bodies = []
    for i, spec in enumerate(scene.bodies):
        if spec.static:
            continue
        b = BodyState(name=spec.name)
        p, q = b.pose.position, b.pose.orientation
        p.x, p.y, p.z = (float(c) for c in states.position[i])
        q.x, q.y, q.z, q.w = (float(c) for c in states.orientation[i])
        bodies.append(b)
    return path, [array(T0 + k * NS // 60, bodies) for k in range(count)]


def totals(peer: Peer) -> dict[str, str]:
    msgs = peer.messages('/diagnostics')
    return {kv.key: kv.value for kv in msgs[-1].status[0].values} if msgs else {}


def settled(peer: Peer, sent: int, timeout: float = 120.0) -> dict[str, str]:
    """The node's totals once they account for ``sent`` messages taken or lost (or at the
    timeout), after one more report."""
    def done() -> bool:
        values = totals(peer)
        return int(values.get('inputs_received', 0)) + int(values.get('inputs_lost', 0)) >= sent
    peer.wait(done, timeout)
    count = len(peer.messages('/diagnostics'))
    peer.wait(lambda: len(peer.messages('/diagnostics')) > count + 1, 10.0)
    return totals(peer)


def report(mode: str, sent: int, values: dict[str, str], kinds: Optional[dict] = None,
           rss: Optional[list[tuple[str, float]]] = None) -> int:
    received = int(values.get('inputs_received', 0))
    lost = int(values.get('inputs_lost', 0))
    steps = int(values.get('steps', 0))
    refused = {k[len('count.'):]: int(v) for k, v in values.items() if k.startswith('count.')}
    whole = {k[len('messages_refused.'):]: int(v) for k, v in values.items()
             if k.startswith('messages_refused.')}
    unaccounted = sent - received - lost
    untaken = received - steps - sum(whole.values())
    print(f'mode: {mode}')
    print(f'messages sent: {sent}')
    print(f'taken by the node: {received}; lost before taken (counted): {lost}')
    print(f'resolved (steps): {steps}; refused whole: {sum(whole.values())} '
          f'{dict(sorted(whole.items()))}')
    print('bodies refused or reset, by reason: '
          + (', '.join(f'{k} {v}' for k, v in sorted(refused.items())) or 'none'))
    print(f'sync_dropped: {values.get("sync_dropped", "?")}')
    print(f'unaccounted: sent - taken - lost = {unaccounted}; '
          f'taken - resolved - refused whole = {untaken}')
    if kinds:
        print('sent by kind: ' + ', '.join(f'{k} {v}' for k, v in sorted(kinds.items())))
    if rss:
        print('node RSS: ' + ', '.join(f'{when} {mb:.1f} MB' for when, mb in rss))
    print(f'diagnostics: level {values.get("_level")} {values.get("_message")}')
    return 0 if unaccounted == 0 and untaken == 0 else 1


def main(argv: Optional[list[str]] = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('mode', choices=('soak', 'fuzz', 'burst'))
    parser.add_argument('--duration', type=float, default=600.0, help='soak: s')
    parser.add_argument('--rate', type=float, default=None,
                        help='Hz (soak: 10, fuzz: 0 = as fast as possible)')
    parser.add_argument('--count', type=int, default=None, help='fuzz 10000, burst 2000')
    parser.add_argument('--domain-id', type=int, default=None)
    args = parser.parse_args(argv)
    domain = args.domain_id if args.domain_id is not None else int(
        os.environ.get('ROS_DOMAIN_ID', '') or 1 + os.getpid() % 90)
    work = Path(tempfile.mkdtemp(prefix='collres-accounting-'))
    kinds: dict[str, int] = {}
    if args.mode == 'soak':
        rate = args.rate or 10.0
        scene, messages = pile_messages(int(args.duration * rate))
    else:
        rate = args.rate or 0.0
        scene = write_scene(work / 'scene.yaml')
        if args.mode == 'fuzz':
            pairs = fuzz_messages(args.count or 10_000)
            for kind, _ in pairs:
                kinds[kind] = kinds.get(kind, 0) + 1
            messages = [m for _, m in pairs]
        else:
            messages = [array(T0 + k * 10_000_000, [body('ball'), body('box', x=1.0, z=0.1)])
                        for k in range(args.count or 2000)]
    node = processes.start('collres_node', ['--ros-args', '--params-file', str(scene),
                                            '-p', 'diagnostics_period:=0.5'],
                           env=processes.ros_env(domain), log=work / 'node.log')
    peer = Peer(domain, 'collres_accounting')
    peer.listen('/diagnostics', DiagnosticArray)
    peer.listen('body_states/corrected', BodyStateArray)
    peer.advertise('body_states', BodyStateArray)
    # the first message opens the publisher's stream (losses before it cannot be counted),
    # the last one, valid and newest, closes the burst
    first, last = messages[0], messages[-1]
    first_ns, last_ns = (m.header.stamp.sec * NS + m.header.stamp.nanosec
                         for m in (first, last))
    if args.mode == 'fuzz':
        box = body('box', x=1.0, z=0.1)
        first_ns, last_ns = T0 - 10 * 10_000_000, T0 + (len(messages) + 10) * 10_000_000
        messages = [array(first_ns, [body('ball'), box])] + messages + [
            array(last_ns, [body('ball'), box])]
        kinds['valid'] = kinds.get('valid', 0) + 2

    def answered(stamp_ns: int) -> bool:
        return any(m.header.stamp.sec * NS + m.header.stamp.nanosec == stamp_ns
                   for m in peer.messages('body_states/corrected'))
    rss: list[tuple[str, float]] = []
    try:
        if not peer.wait(lambda: peer.connected('body_states') and bool(totals(peer)), 60.0):
            print(f'error: the node did not come up: {node.output()}', file=sys.stderr)
            return 1
        rss.append(('start', rss_mb(node.pid)))
        start = time.monotonic()
        peer.publish('body_states', messages[0])
        if not peer.wait(lambda: answered(first_ns), 30.0):
            print('error: the first message got no answer', file=sys.stderr)
            return 1
        for k, msg in enumerate(messages[1:], 1):
            if rate > 0:
                due = start + k / rate
                while time.monotonic() < due:
                    time.sleep(min(0.005, max(due - time.monotonic(), 0.0)))
            peer.publish('body_states', msg)
            if k == len(messages) // 2:
                rss.append(('middle', rss_mb(node.pid)))
        peer.wait(lambda: answered(last_ns), 120.0)
        values = settled(peer, len(messages))
        rss.append(('end', rss_mb(node.pid)))
        last = peer.messages('/diagnostics')[-1].status[0]
        values['_level'] = str(int.from_bytes(last.level, 'little')
                               if isinstance(last.level, bytes) else last.level)
        values['_message'] = last.message
        print(f'wall time: {time.monotonic() - start:.1f} s; node log: {node.log_path}')
        return report(args.mode, len(messages), values, kinds, rss)
    finally:
        peer.close()
        processes.stop(node)


if __name__ == '__main__':
    sys.exit(main())
