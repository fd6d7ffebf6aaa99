"""Random tumbling drops at low rates: does a thin body pass into or through the floor?

The drops of ``test/core/test_no_tunnelling.py`` (``tumbling_drop``: a 1 m x 1 m x 0.1 m
plate or a 0.4 x 0.1 x 0.05 m stick dropped from 0.3 to 1 m onto a 0.1 m floor box, turned
at random, spinning at up to 8 rad/s, sliding at up to 1 m/s, 3 s through the core as
collres_sim closes the loop), for more seeds than the test runs. Per drop: the deepest its
lowest corner went below the floor's top, and where it ended. Through: it ended below the
floor's bottom; deep: it ended more than 3 mm in.

    .venv/bin/python bench/tunnelling.py [--drops 30] [--rate 10] [--body plate|stick]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / 'test' / 'core'))

from test_no_tunnelling import FLOOR, THIN, tumbling_drop  # noqa: E402


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--drops', type=int, default=30)
    parser.add_argument('--rate', type=float, default=10.0)
    parser.add_argument('--body', choices=sorted(THIN), default='plate')
    parser.add_argument('--seed', type=int, default=0, help='first seed')
    args = parser.parse_args()
    through = deep = 0
    worst = 0.0
    for seed in range(args.seed, args.seed + args.drops):
        lowest = tumbling_drop(THIN[args.body], args.rate, seed)
        deepest, last = lowest.min(), lowest[-1]
        through += last < -FLOOR
        deep += -FLOOR <= last < -0.003
        worst = min(worst, deepest)
        if last < -0.003:
            print(f'seed {seed}: deepest {-deepest * 1e3:.1f} mm, ended {-last * 1e3:.1f} mm in')
    print(f'{args.body} at {args.rate:g} Hz, {args.drops} drops: {through} through the floor, '
          f'{deep} ended more than 3 mm in, deepest {-worst * 1e3:.1f} mm')
    return 0


if __name__ == '__main__':
    sys.exit(main())
