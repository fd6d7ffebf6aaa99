"""The step budget: N boxes at one point, one step, in-process: wall time and peak memory.

Every body inside every validation limit, all at the origin: the broad phase gives
N (N - 1) / 2 pairs, each a deep overlap. Within the budget (``solver.max_pairs``,
``solver.max_contacts``) the step queries only the deepest pairs and keeps the deepest
rows; ``--unbounded`` sets both budgets to their maximum (what the step costs without
one; above a few hundred boxes that takes minutes and gigabytes). Each size runs in a
child process of its own, so its peak RSS is its own.

Usage::

    .venv/bin/python bench/bench_budget.py [--sizes 500 1000 2000] [--unbounded]
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time

CHILD = '''
import json, resource, sys, time
import numpy as np
from collres_ros.core.pipeline import Resolver
from collres_ros.core.types import BodyInput
from collres_ros.ros import params
n, unbounded = int(sys.argv[1]), sys.argv[2] == '1'
names = [f'b{k}' for k in range(n)]
values = {'bodies': names, **{f'body.{m}.shape': 'box' for m in names},
          **{f'body.{m}.size': [0.1, 0.1, 0.1] for m in names}}
if unbounded:
    values.update({'solver.max_pairs': 10_000_000, 'solver.max_contacts': 10_000_000})
resolver = Resolver.for_scene(params.scene_from_values(values))
inputs = [BodyInput(m, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0, 1.0), (0.0, 0.0, 0.0), (0.0, 0.0, 0.0),
                    'world', 'world') for m in names]
rss0 = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
start = time.perf_counter()
step = resolver.resolve(10**12, inputs)
wall = time.perf_counter() - start
print(json.dumps({'bodies': n, 'wall_s': wall, 'contacts': int(step.report.contacts.count),
                  'budget_dropped': list(step.budget),
                  'finite': bool(np.isfinite(step.states.position).all()),
                  'rss_before_mb': rss0 / 1024,
                  'peak_rss_mb': resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024}))
'''


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--sizes', type=int, nargs='+', default=[500, 1000, 2000])
    parser.add_argument('--unbounded', action='store_true',
                        help='budgets at their maximum: the cost without a budget')
    args = parser.parse_args()
    with open('/proc/loadavg') as load:
        print(f'load: {load.read().strip()}')
    for n in args.sizes:
        started = time.perf_counter()
        result = subprocess.run([sys.executable, '-c', CHILD, str(n),
                                 '1' if args.unbounded else '0'],
                                capture_output=True, text=True, env=os.environ)
        if result.returncode != 0:
            print(f'{n} bodies: failed ({result.returncode}): {result.stderr[-500:]}')
            continue
        row = json.loads(result.stdout)
        print(f"{n:5d} boxes at one point: step {row['wall_s']:.3f} s, "
              f"{row['contacts']} contacts, dropped (pairs, rows) {row['budget_dropped']}, "
              f"peak RSS {row['peak_rss_mb']:.0f} MB (start {row['rss_before_mb']:.0f} MB), "
              f"finite {row['finite']}; process {time.perf_counter() - started:.1f} s")
    return 0


if __name__ == '__main__':
    sys.exit(main())
