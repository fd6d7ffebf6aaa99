"""A long random run of the mirror law (not in ``make test``: 30 s to minutes, not seconds).

    .venv/bin/python bench/mirror_scan.py [--seeds 14 75] [--threshold 1e-6] [--spin-rows-off]

The random mirror hits of test/core/test_mirror_friction.py (``mirror_hit``: a box on
another box or on a fixed wall through 2 or 4 points mirror images of each other through
y = 0, e 0-1, friction 0.2-1.5, sliding and spinning in the mirror plane, impact or
persistent, 30-240 Hz), seed by seed as that file's whatever-the-seed test draws them: per
seed, on another box and on a fixed wall, 200 hits through two points and 150 through four.
The law: a point's impulses are its mirror image's (normal equal, friction mirrored) within
``--threshold`` of the largest normal impulse.

Prints each asymmetric hit (seed, partner, points, case index, asymmetry, kind, rate) and
the count. With ``--spin-rows-off`` each asymmetric hit is stepped again with the bodies'
rolling resistance and torsional friction at 0 (no spin row): an asymmetry that vanishes
so comes from the spin rows' update after the manifold's, not from the manifold's own solve.
Each hit found is to become a plain regression test once a change makes it symmetric
(test/core/test_mirror_friction.py). Exit code 1 on any asymmetric hit.
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import sys
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, '..'))
sys.path.insert(0, os.path.join(HERE, '..', 'test', 'core'))

from test_mirror_friction import asymmetry, mirror_hit  # noqa: E402

CLASSES = ((False, 1, 200), (False, 2, 150), (True, 1, 200), (True, 2, 150))


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--seeds', type=int, nargs=2, default=(14, 75), metavar=('FIRST', 'END'),
                        help='seeds FIRST .. END - 1')
    parser.add_argument('--threshold', type=float, default=1e-6,
                        help='asymmetry allowed, over the largest normal impulse')
    parser.add_argument('--spin-rows-off', action='store_true',
                        help='step each asymmetric hit again without rolling resistance and '
                             'torsional friction')
    args = parser.parse_args()
    start = time.perf_counter()
    hits = asymmetric = 0
    for seed in range(*args.seeds):
        for fixed, pairs, count in CLASSES:
            rng = np.random.default_rng(seed)
            for case in range(count):
                bodies, before, contacts, dt = mirror_hit(rng, fixed=fixed, pairs=pairs)
                hits += 1
                error = asymmetry(bodies, before, contacts, dt)
                if not error > args.threshold:
                    continue
                asymmetric += 1
                kind = 'impact' if contacts.kind[0] == 1 else 'persistent'
                line = (f'seed {seed} {"wall" if fixed else "box"} {2 * pairs} points case '
                        f'{case}: {error:.3g} ({kind}, {round(1 / dt)} Hz)')
                if args.spin_rows_off:
                    still = [dataclasses.replace(b, rolling_resistance=0.0,
                                                 torsional_friction=0.0) for b in bodies]
                    line += f'; without spin rows {asymmetry(still, before, contacts, dt):.3g}'
                print(line, flush=True)
    print(f'{hits} hits (seeds {args.seeds[0]} .. {args.seeds[1] - 1}) in '
          f'{time.perf_counter() - start:.1f} s: {asymmetric} asymmetric beyond '
          f'{args.threshold:g}')
    return 1 if asymmetric else 0


if __name__ == '__main__':
    sys.exit(main())
