"""The node's ROS edge in-process, without the physics: decode, resolve, encode, publish.

    .venv/bin/python bench/bench_edge.py [--sizes 10 100 1000] [--steps 200]

What ``collres_node`` does per ``body_states`` message, minus ``World.step``:
the settled pile of bench/pile.py (one real World.step gives its contacts),
then per step: decode the serialised BodyStateArray, ``Resolver.resolve``
with a world that returns that step's result at once (so what is timed is the
Resolver's own work), encode every output (corrected states, contacts,
contact markers) and publish them with rclpy to topics that a listener in
another ROS context subscribes to (so the middleware really sends them).
Prints the median and the 10th percentile of each part and of their sum, the
node overhead; a shared machine inflates medians, the 10th percentile shows
what the code costs when it gets the CPU.

Runs against the checkout the interpreter imports (PYTHONPATH): an older one
without ``collres_ros.ros.codec.StatesCodec`` is measured on its own path
(rclpy deserialisation, BodyInputs, message objects, rclpy serialisation).
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

from bench_latency import Listener, input_bytes, settled_pile  # noqa: E402

PARTS = ('decode', 'resolve', 'encode', 'publish')


class CannedWorld:
    """A World stand-in that returns one recorded StepResult at once."""

    def __init__(self, world: Any, result: Any) -> None:
        self.world, self.result = world, result
        self.settings = world.settings
        self.budget = world.budget   # the recorded step's (broad-phase pairs, rows) dropped

    def step(self, *args: Any, **kwargs: Any) -> Any:
        return self.result

    def forget(self, index: Any, last_poses: Any = None) -> None:
        pass

    def set_material(self, *args: Any, **kwargs: Any) -> None:
        pass


def measure(count: int, steps: int, settle: float, domain: int) -> dict[str, np.ndarray]:
    import rclpy
    from rclpy.qos import QoSProfile, ReliabilityPolicy
    from rclpy.serialization import deserialize_message
    from visualization_msgs.msg import MarkerArray

    from collres_ros.core.config import SolverSettings
    from collres_ros.core.pipeline import Resolver
    from collres_ros.core.world import World
    from collres_ros.msg import BodyStateArray, ContactArray
    from collres_ros.ros import messages
    bodies, state, _ = settled_pile(count, settle)
    data = input_bytes(bodies, state)
    world = World(bodies, SolverSettings())
    msg = deserialize_message(data, BodyStateArray)
    resolver = Resolver(bodies, world=world, initial=state)
    stamp = 10**12
    first = resolver.resolve(stamp, messages.inputs_from_array(msg))
    result = world.step(resolver.state, resolver.state, 1 / 120, np.ones(len(bodies), bool))
    resolver.world = CannedWorld(world, result)
    names = [b.name for b in bodies]
    new = hasattr(messages, 'OutputEncoder')
    if new:
        from collres_ros.core.types import InputBatch
        from collres_ros.ros.codec import StatesCodec
        codec = StatesCodec(len(bodies))
        encoder = messages.OutputEncoder(names, 'world')
    context = rclpy.Context()
    rclpy.init(context=context, domain_id=domain)
    node = rclpy.create_node('collres_bench_edge', context=context)
    qos = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
    publishers = {'body_states/corrected': node.create_publisher(
        BodyStateArray, 'body_states/corrected', qos),
        'contacts': node.create_publisher(ContactArray, 'contacts', qos),
        'contact_markers': node.create_publisher(MarkerArray, 'contact_markers', qos)}
    listener = Listener(domain)
    deadline = time.monotonic() + 30
    while not all(p.get_subscription_count() for p in publishers.values()):
        if time.monotonic() > deadline:
            raise RuntimeError('listener not matched')
        time.sleep(0.05)
    times = {part: [] for part in PARTS}
    contacts = first.report.contacts.count
    try:
        for k in range(steps + 10):
            stamp += 8_333_333
            raw = data[:4] + int(stamp // 10**9).to_bytes(4, 'little') + \
                int(stamp % 10**9).to_bytes(4, 'little') + data[12:]
            t0 = time.perf_counter()
            if new:
                d = codec.decode(raw)
                inputs: Any = InputBatch(d.names, d.values, d.frame_id, d.frame_id)
            else:
                inputs = messages.inputs_from_array(deserialize_message(raw, BodyStateArray))
            t1 = time.perf_counter()
            step = resolver.resolve(stamp, inputs)
            t2 = time.perf_counter()
            if new:
                outputs = [(topic, payload) for topic, _, payload in encoder.encode(step)]
            else:
                outputs = messages.build_outputs(step, 'world')
            t3 = time.perf_counter()
            for topic, payload in outputs:
                publishers[topic].publish(payload)
            t4 = time.perf_counter()
            contacts = step.report.contacts.count
            if k >= 10:
                for part, dt in zip(PARTS, (t1 - t0, t2 - t1, t3 - t2, t4 - t3)):
                    times[part].append(1e3 * dt)
    finally:
        listener.close()
        node.destroy_node()
        rclpy.try_shutdown(context=context)
    out = {part: np.array(v) for part, v in times.items()}
    out['overhead'] = sum(out[p] for p in PARTS)
    out['contacts'] = np.array([contacts])
    return out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--sizes', type=int, nargs='+', default=[10, 100, 1000])
    parser.add_argument('--steps', type=int, default=200)
    parser.add_argument('--settle', type=float, default=0.5, help='settling time, s')
    parser.add_argument('--domain', type=int, default=int(os.environ.get('ROS_DOMAIN_ID', 90)))
    args = parser.parse_args(argv)
    print('| bodies | contacts | ' + ' | '.join(f'{p} ms' for p in PARTS)
          + ' | overhead ms (sum) |')
    print('|---' * (len(PARTS) + 3) + '|')
    for count in args.sizes:
        r = measure(count, args.steps if count < 1000 else max(args.steps // 4, 20),
                    args.settle, args.domain)
        cell = (lambda v: f'{np.median(v):.3f} ({np.percentile(v, 10):.3f})')
        print(f'| {count} | {int(r["contacts"][0])} | '
              + ' | '.join(cell(r[p]) for p in PARTS) + f' | {cell(r["overhead"])} |',
              flush=True)
    print('median (10th percentile) per step; resolve = Resolver.resolve with a canned '
          'World.step; publish = rclpy publish of the three topics, one subscriber each')
    return 0


if __name__ == '__main__':
    sys.exit(main())
