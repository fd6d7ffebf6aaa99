"""collres_replay throughput: steps/s on a scene with every output topic, and where time goes.

    .venv/bin/python bench/bench_replay.py [--params config/scenes/pile.yaml] [--repeat 3]
        [--profile]

Records the scene's inputs offline (``body_states`` only), then replays them
``--repeat`` times into new bags with every output topic of the node
(corrected states, contacts, contact markers, diagnostics) and prints the
best and median steps/s, and how much of the wall time ``World.step`` (the
physics core) took: steps/s without it is what the ROS side alone sustains.
``--profile`` adds a cProfile of one replay, the functions with the largest
cumulative time. Works against an older checkout
too (PYTHONPATH), whose functions lived in ``collres_ros.sim`` / ``.replay``.
"""

from __future__ import annotations

import argparse
import cProfile
import io
import pstats
import statistics
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _api():
    """(load_sim_scene, run_offline, replay) of this checkout (or of an older layout)."""
    try:
        from collres_ros.ros.offline import replay, run_offline
        from collres_ros.ros.simulation import load_sim_scene
    except ImportError:   # the layout before collres_ros.ros.offline existed
        from collres_ros.replay import replay
        from collres_ros.sim import load_sim_scene, run_offline
    return load_sim_scene, run_offline, replay


class WorldTimer:
    """Sum the wall time of every World.step call (wraps the class method)."""

    def __init__(self) -> None:
        from collres_ros.core.world import World
        self.total = 0.0
        step = World.step

        def timed(world, *args, **kwargs):
            start = time.perf_counter()
            try:
                return step(world, *args, **kwargs)
            finally:
                self.total += time.perf_counter() - start
        World.step = timed


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--params', default=str(ROOT / 'config' / 'scenes' / 'pile.yaml'))
    parser.add_argument('--duration', type=float, help='s of simulated time (default: scene)')
    parser.add_argument('--repeat', type=int, default=3)
    parser.add_argument('--profile', action='store_true')
    parser.add_argument('--top', type=int, default=25)
    args = parser.parse_args(argv)
    load_sim_scene, run_offline, replay = _api()
    params = Path(args.params)
    with tempfile.TemporaryDirectory(prefix='collres_bench_replay_') as tmp:
        bag = Path(tmp) / 'input'
        start = time.perf_counter()
        run_offline(load_sim_scene(params, args.duration), bag, topics=['body_states'])
        print(f'recorded the inputs of {params.name} in {time.perf_counter() - start:.1f} s')
        rates, rest, results = [], [], []
        timer = WorldTimer()
        for k in range(args.repeat):
            before = timer.total
            summary = replay(bag, Path(tmp) / f'out{k}', params)
            world = timer.total - before
            rates.append(summary.steps / summary.wall_s)
            rest.append(summary.steps / max(summary.wall_s - world, 1e-9))
            results.append((summary, world))
        s, world = results[0]
        print(f'replay {params.name}: {s.steps} steps, {s.messages_out} messages out, '
              f'contacts {sum(s.contacts.values())}; steps/s best {max(rates):.1f}, '
              f'median {statistics.median(rates):.1f} (of {args.repeat}); World.step '
              f'{1e3 * world / s.steps:.2f} ms/step = {100 * world / s.wall_s:.0f} % of the wall '
              f'time; without it: best {max(rest):.1f} steps/s, median '
              f'{statistics.median(rest):.1f}')
        if args.profile:
            profile = cProfile.Profile()
            profile.enable()
            replay(bag, Path(tmp) / 'profiled', params)
            profile.disable()
            text = io.StringIO()
            pstats.Stats(profile, stream=text).sort_stats('cumulative').print_stats(args.top)
            print(text.getvalue())
    return 0


if __name__ == '__main__':
    sys.exit(main())
