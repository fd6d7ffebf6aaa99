"""The node's work to an answer, in one process: decode, check, resolve, encode, paced.

Usage::

    .venv/bin/python bench/bench_answer.py [--sizes 100 1000] [--rates 100 30] [--steps 400]

For each size the settled pile of ``bench/bench_latency.py`` (its params file read back, its
estimator input: the settled poses, zero twists, a new stamp each step) goes through what
``collres_node``'s ``body_states`` callback does before and after its answer, without DDS:
``StatesCodec.decode``, ``Resolver.resolve`` (``check_inputs`` and ``World.step`` inside it,
``Sleep.before`` inside that), the answer's encode, then ``contacts`` and ``contact_markers``.
One step per period of the rate, the thread asleep in between (as the node's input thread
waits for its next message): on a shared machine whatever runs first after a wake-up pays
for the caches other processes took, and that is the node's cost, not a loop's. Printed:
thread CPU medians (ms) over ``--steps`` steps after 2 s of warm-up (the pile falls asleep),
and the answer's CPU beyond ``World.step`` (decode + resolve + answer encode - World.step:
what the node's ``overhead`` measures, without the publish). Run the trees to compare
alternately (each with its own interpreter); thread CPU, not wall time, so what other
processes take is left out.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path
from typing import Any, Callable

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

import bench_latency  # noqa: E402


def _timed(owner: Any, name: str, spent: dict[str, float], key: str) -> None:
    """Wrap ``owner.name`` so that its thread CPU adds up in ``spent[key]``."""
    function: Callable[..., Any] = getattr(owner, name)

    def wrapper(*args: Any, **kwargs: Any) -> Any:
        start = time.thread_time()
        try:
            return function(*args, **kwargs)
        finally:
            spent[key] = spent.get(key, 0.0) + time.thread_time() - start
    setattr(owner, name, wrapper)


def measure(count: int, rate: float, steps: int, workdir: Path) -> dict[str, float]:
    """Median thread CPU (ms) per part of a step of the settled ``count``-body pile."""
    from collres_ros.core import pipeline
    from collres_ros.core.pipeline import Resolver
    from collres_ros.core.types import InputBatch
    from collres_ros.ros import codec, messages, params
    bodies, state, _ = bench_latency.settled_pile(count, 3.0 if count >= 1000 else 2.0)
    scene = params.load_scene(bench_latency.write_scene(workdir / f'pile{count}.yaml', bodies,
                                                        state))
    template = bytearray(bench_latency.input_bytes(bodies, state))
    resolver = Resolver.for_scene(scene)
    states = codec.StatesCodec(max_bodies=scene.node.max_message_bodies)
    encoder = messages.OutputEncoder(scene.names, scene.world_frame, scene.bodies)
    spent: dict[str, float] = {}
    _timed(resolver.world, 'step', spent, 'World.step')
    _timed(resolver.world.sleep, 'before', spent, 'Sleep.before')
    _timed(pipeline, 'check_inputs', spent, 'check_inputs')
    period = int(round(1e9 / rate))
    stamp = bench_latency.T0
    rows: dict[str, list[float]] = {}
    for k in range(int(2 * rate) + steps):
        stamp += period
        data = bytes(bench_latency.with_stamp(template, stamp))
        time.sleep(1.0 / rate)
        spent.clear()
        t0 = time.thread_time()
        decoded = states.decode(data)
        t1 = time.thread_time()
        step = resolver.resolve(decoded.stamp_ns, InputBatch(decoded.names, decoded.values,
                                                             decoded.frame_id,
                                                             decoded.frame_id))
        t2 = time.thread_time()
        encoder.corrected(step)
        t3 = time.thread_time()
        encoder.encode(step, per_body=False, marker_lifetime=scene.node.marker_lifetime,
                       corrected=False)
        t4 = time.thread_time()
        if k < int(2 * rate):
            continue
        parts = {'decode': t1 - t0, 'resolve': t2 - t1, 'answer encode': t3 - t2,
                 'contacts + markers': t4 - t3, **spent,
                 'beyond World.step': t3 - t0 - spent.get('World.step', 0.0)}
        for key, value in parts.items():
            rows.setdefault(key, []).append(1e3 * value)
    out = {key: float(np.median(values)) for key, values in rows.items()}
    out['asleep'] = float(resolver.sleep_counts().get('sleeping_bodies', 0))
    out['contacts'] = float(step.report.contacts.count)
    return out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--sizes', type=int, nargs='+', default=[100, 1000])
    parser.add_argument('--rates', type=float, nargs='+', default=[100.0, 30.0])
    parser.add_argument('--steps', type=int, default=400)
    args = parser.parse_args(argv)
    rates = (args.rates + [args.rates[-1]] * len(args.sizes))[:len(args.sizes)]
    keys = ('decode', 'check_inputs', 'Sleep.before', 'World.step', 'resolve', 'answer encode',
            'beyond World.step', 'contacts + markers')
    print('| bodies @ Hz | asleep | contacts | ' + ' | '.join(keys) + ' |')
    print('|---' * (3 + len(keys)) + '|')
    with tempfile.TemporaryDirectory(prefix='collres_answer_') as tmp:
        for count, rate in zip(args.sizes, rates):
            r = measure(count, rate, args.steps, Path(tmp))
            print(f'| {count} @ {rate:g} | {r["asleep"]:.0f} | {r["contacts"]:.0f} | '
                  + ' | '.join(f'{r.get(k, float("nan")):.3f}' for k in keys) + ' |',
                  flush=True)
    print('thread CPU medians, ms a step, one step per period (see the docstring); resolve '
          'holds check_inputs and World.step, World.step holds Sleep.before; beyond '
          'World.step = decode + resolve + answer encode - World.step')
    return 0


if __name__ == '__main__':
    sys.exit(main())
