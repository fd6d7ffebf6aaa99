"""Input -> corrected-output latency of collres_node over DDS (localhost), p50/p99.

Starts the real collres_node as a child process in a private ROS_DOMAIN_ID,
publishes BodyStateArray steps of N spheres resting on a floor (N contacts
per step) one at a time, and times each step from publish to the reception
of its body_states/corrected (same host clock). Usage:

    .venv/bin/python bench/bench_latency.py [--bodies 10 100] [--steps 300]
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import threading
import time
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / 'test'))

from ros_harness import Peer  # noqa: E402

from diagnostic_msgs.msg import DiagnosticArray  # noqa: E402

from collres_ros.ros import processes  # noqa: E402
from collres_ros.ros.messages import stamp_ns, to_stamp  # noqa: E402
from collres_ros.msg import BodyState, BodyStateArray  # noqa: E402


def scene_file(path: Path, count: int) -> Path:
    side = int(np.ceil(np.sqrt(count)))
    names = [f'b{i}' for i in range(count)]
    lines = ['/**:', '  ros__parameters:', '    world_frame: world',
             f'    bodies: [floor, {", ".join(names)}]', '    body:',
             '      floor: {shape: box, size: [100.0, 100.0, 0.2], static: true, '
             'position: [0.0, 0.0, -0.1]}']
    for i, name in enumerate(names):
        x, y = 0.2 * (i % side), 0.2 * (i // side)
        lines.append(f'      {name}: {{shape: sphere, size: [0.05], position: [{x}, {y}, 0.05]}}')
    path.write_text('\n'.join(lines) + '\n')
    return path


def measure(count: int, steps: int, domain: int, workdir: Path) -> dict[str, float]:
    scene = scene_file(workdir / f'scene{count}.yaml', count)
    node = processes.start('collres_node', ['--ros-args', '--params-file', str(scene)],
                           env=processes.ros_env(domain), log=workdir / f'node{count}.log')
    peer = Peer(domain, 'collres_bench')
    arrivals: dict[int, float] = {}
    arrived = threading.Event()

    def on_corrected(msg: BodyStateArray) -> None:
        arrivals[stamp_ns(msg.header.stamp)] = time.perf_counter()
        arrived.set()
    peer.node.create_subscription(BodyStateArray, 'body_states/corrected', on_corrected, 10)
    diagnostics: list[Any] = []
    peer.node.create_subscription(DiagnosticArray, '/diagnostics', diagnostics.append, 10)
    peer.advertise('body_states', BodyStateArray)
    try:
        if not peer.wait(lambda: peer.connected('body_states') and
                         peer.node.count_publishers('body_states/corrected') > 0, 30.0):
            raise RuntimeError(f'node did not come up: {node.output()}')
        side = int(np.ceil(np.sqrt(count)))
        bodies = []
        for i in range(count):
            b = BodyState(name=f'b{i}')
            b.pose.position.x, b.pose.position.y = 0.2 * (i % side), 0.2 * (i // side)
            b.pose.position.z, b.pose.orientation.w = 0.05, 1.0
            bodies.append(b)
        latencies = []
        warmup = 20
        for k in range(steps + warmup):
            stamp = 10**12 + k * 10**9 // 240
            msg = BodyStateArray(bodies=bodies)
            msg.header.frame_id = 'world'
            msg.header.stamp = to_stamp(stamp)
            arrived.clear()
            sent = time.perf_counter()
            peer.publish('body_states', msg)
            deadline = time.monotonic() + 10.0
            # an Event, not a busy loop: the spin thread needs the GIL
            while stamp not in arrivals:
                if not arrived.wait(max(deadline - time.monotonic(), 0.0)):
                    raise RuntimeError(f'no answer for step {k}')
                arrived.clear()
            if k >= warmup:
                latencies.append(arrivals[stamp] - sent)
        ms = np.array(latencies) * 1e3
        peer.wait(lambda: bool(diagnostics), 3.0)
        values = {kv.key: kv.value for kv in diagnostics[-1].status[0].values} \
            if diagnostics else {}
        return {'bodies': count, 'steps': steps, 'p50': float(np.percentile(ms, 50)),
                'p90': float(np.percentile(ms, 90)), 'p99': float(np.percentile(ms, 99)),
                'max': float(ms.max()),
                'resolve': float(values.get('step_time_mean_ms', 'nan')),
                'callback': float(values.get('callback_time_mean_ms', 'nan'))}
    finally:
        peer.close()
        processes.stop(node)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--bodies', type=int, nargs='+', default=[10, 100])
    parser.add_argument('--steps', type=int, default=300)
    parser.add_argument('--domain', type=int, default=90 + os.getpid() % 10)
    args = parser.parse_args()
    print('| bodies | steps | p50 ms | p90 ms | p99 ms | max ms | node: resolve ms | node: '
          'callback ms |')
    print('|---|---|---|---|---|---|---|---|')
    with tempfile.TemporaryDirectory() as tmp:
        for count in args.bodies:
            r = measure(count, args.steps, args.domain, Path(tmp))
            print(f'| {count} | {r["steps"]} | {r["p50"]:.2f} | {r["p90"]:.2f} | '
                  f'{r["p99"]:.2f} | {r["max"]:.2f} | {r["resolve"]:.2f} | '
                  f'{r["callback"]:.2f} |', flush=True)
    return 0


if __name__ == '__main__':
    sys.exit(main())
