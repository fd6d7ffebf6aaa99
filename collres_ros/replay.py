"""collres_replay: run a recorded rosbag2 bag through the core offline, deterministically.

::

    collres_replay IN_BAG OUT_BAG [--params FILE] [--storage mcap|sqlite3] [--namespace NS]

Reads the node's input topics from IN_BAG (mcap or sqlite3): the batched
``body_states`` (one step per message), or else the per-body
``bodies/<name>/pose`` + ``bodies/<name>/twist``, grouped by header stamp (a
step when every dynamic body of the scene has both for the same stamp, as the
node's exact sync does). Every step goes through the same ``Resolver`` and the
same output builder as ``collres_node`` (``collres_ros.ros.offline.replay``), and
every output topic is written to OUT_BAG at the log time of the input message
that completed the step (the node publishes its answer on receipt). Progress
goes to stderr, a summary to stdout; errors exit 1 with one ``error: ...`` line.

Same input, same output: the core is deterministic, so two replays of a bag
give identical decoded messages.
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path
from typing import Callable, Sequence

from collres_ros.ros import cli


def _progress_printer() -> Callable[[int, int], None] | None:
    """Progress on stderr at most twice a second, when stdout and stderr are terminals."""
    from collres_ros.ros.console import progress_printer
    return progress_printer('replay')


def parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog='collres_replay',
        description='Run a recorded rosbag2 bag through the collres core offline and write '
                    'every output topic of collres_node to a new bag.')
    p.add_argument('in_bag', help='input bag directory (mcap or sqlite3)')
    p.add_argument('out_bag', help='output bag directory (must not exist)')
    p.add_argument('--params', help='params file of the scene, read as collres_node in '
                                    '--namespace reads it (default: the params recorded in '
                                    'IN_BAG by collres_sim, collres_replay or collres_demo)')
    p.add_argument('--storage', help='output storage: mcap or sqlite3 (default: as the input)')
    p.add_argument('--namespace', default='/',
                   help='namespace of the node: its topics, and the sections of the params '
                        'file that apply to it (default: /)')
    p.add_argument('--topics', help='write only these output topics, comma separated '
                                    '(relative names, e.g. body_states/corrected,contacts; '
                                    'default: every output topic)')
    p.add_argument('--wait', type=cli.number(0.0, 3600.0), default=20.0,
                   help='with robot_description_topic in --params: s to wait for the URDF on '
                        'robot_description (as collres_node takes it)')
    p.add_argument('--quiet', action='store_true',
                   help='no progress line (it is drawn on a terminal only anyway)')
    return p


def _run(args: argparse.Namespace) -> int:
    from collres_ros.ros.bag import BagError
    from collres_ros.ros.offline import replay
    topics = None if args.topics is None else \
        tuple(t.strip() for t in args.topics.split(',') if t.strip())
    overrides = {}
    if args.params:   # robot_description_topic: the URDF from the topic, as the node takes it
        from collres_ros.ros import description, params
        values = params.load_scene(args.params, args.namespace).values
        if values['robot_description_topic'] and not values['robot_description']:
            overrides['robot_description'] = description.fetch(
                'collres_replay', ['--ros-args', '-r', f'__ns:={args.namespace}'], args.wait)
    try:
        summary = replay(Path(args.in_bag), Path(args.out_bag),
                         Path(args.params) if args.params else None,
                         args.storage, args.namespace,
                         None if args.quiet else _progress_printer(), topics,
                         overrides=overrides)
    except BagError as failure:
        return cli.error(failure)
    try:
        print(f'wrote {args.out_bag}')
        for line in summary.lines():
            print(line)
        sys.stdout.flush()
    except BrokenPipeError:  # e.g. piped into head: the bag is written, that is what counts
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
    return 0


def main(argv: Sequence[str] | None = None) -> int:
    """Console script ``collres_replay``: 0 when the bag was written, 1 with ``error: ...``."""
    args = parser().parse_args(argv)
    return cli.run(lambda: _run(args))


if __name__ == '__main__':
    sys.exit(main())
