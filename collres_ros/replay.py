"""collres_replay: run a recorded rosbag2 bag through the core offline, deterministically.

::

    collres_replay IN_BAG OUT_BAG --params FILE [--storage mcap|sqlite3] [--namespace NS]

Reads the node's input topics from IN_BAG (mcap or sqlite3): the batched
``body_states`` (one step per message), or else the per-body
``bodies/<name>/pose`` + ``bodies/<name>/twist``, grouped by header stamp (a
step when every dynamic body of the scene has both for the same stamp, as the
node's exact sync does). Every step goes through the same ``Resolver`` and the
same output builder as ``collres_node``, and every output topic is written to
OUT_BAG at the log time of the input message that completed the step (the
node publishes its answer on receipt). Progress goes to stderr, a summary to
stdout; errors exit 1 with one ``error: ...`` line.

Same input, same output: the core is deterministic, so two replays of a bag
give identical decoded messages.
"""

from __future__ import annotations

import argparse
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Iterator, Sequence

STATE_NAMES = {1: 'IMPACT', 2: 'RESTING', 3: 'SLIDING', 4: 'STICKING'}


class ReplayError(Exception):
    """A user error: one line, printed as ``error: ...``."""


@dataclass
class Step:
    """One resolution step read from the input bag."""

    stamp: int          # ns, header stamp of the inputs
    log_time: int       # ns, receive time of the message that completed the step
    inputs: list[Any]   # BodyInput list for Resolver.resolve
    per_body: bool      # True when it came from per-body topics


@dataclass
class ReplaySummary:
    steps: int = 0
    messages_in: int = 0
    messages_out: int = 0
    contacts: dict[str, int] = field(default_factory=dict)
    rejected: dict[str, int] = field(default_factory=dict)
    incomplete: int = 0     # per-body stamps that never got every body
    wall_s: float = 0.0

    def lines(self) -> list[str]:
        rate = self.steps / self.wall_s if self.wall_s > 0 else float('inf')
        msg_rate = (self.messages_in + self.messages_out) / self.wall_s \
            if self.wall_s > 0 else float('inf')
        contacts = ', '.join(f'{k} {self.contacts.get(k, 0)}' for k in STATE_NAMES.values())
        rejected = ', '.join(f'{k} {v}' for k, v in sorted(self.rejected.items())) or 'none'
        out = [f'steps: {self.steps} ({rate:.0f} steps/s, {msg_rate:.0f} messages/s, '
               f'{self.wall_s:.2f} s)',
               f'messages: {self.messages_in} read, {self.messages_out} written',
               f'contacts: {contacts}',
               f'rejected inputs: {rejected}']
        if self.incomplete:
            out.append(f'incomplete per-body stamps skipped: {self.incomplete}')
        return out


def topic_name(relative: str, namespace: str) -> str:
    """Absolute topic of a relative name in ``namespace`` ('/' or '/robot')."""
    return namespace.rstrip('/') + '/' + relative


def _stamp_ns(stamp: Any) -> int:
    return int(stamp.sec) * 10**9 + int(stamp.nanosec)


class BatchedSource:
    """One step per body_states message."""

    def __init__(self, topic: str) -> None:
        self.topic = topic
        self.incomplete = 0

    def steps(self, reader: Any) -> Iterator[Step]:
        from collres_ros import messages
        for m in reader.messages([self.topic]):
            yield Step(_stamp_ns(m.msg.header.stamp), m.log_time,
                       messages.inputs_from_array(m.msg), False)


def read_steps(reader: Any, scene: Any, namespace: str) -> tuple[Any, int]:
    """A step source (``.steps(reader)``, ``.incomplete``) for a bag and its step count.

    Batched if the bag has body_states, else per body.

    ReplayError when the bag has none of the input topics.
    """
    topics = reader.topics
    batched = topic_name('body_states', namespace)
    if batched in topics:
        return BatchedSource(batched), reader.topic_count(batched)
    dynamic = [b.name for b in scene.bodies if not b.static]
    wanted = {}
    for body in scene.bodies:
        for kind in ('pose', 'twist'):
            name = topic_name(f'bodies/{body.name}/{kind}', namespace)
            if name in topics:
                wanted[name] = (body.name, kind)
    if not wanted:
        raise ReplayError(f'no input topics in {reader.path}: expected {batched} or '
                          f'{topic_name("bodies/<name>/pose", namespace)} and .../twist '
                          f'(found: {", ".join(sorted(topics)) or "none"})')
    grouper = PerBodyGrouper(wanted, dynamic)
    return grouper, min(reader.topic_count(t) for t in wanted)


class PerBodyGrouper:
    """Group per-body pose/twist messages by stamp; a step once every dynamic body has both.

    Stamps older than a completed one can no longer complete in order: they
    are dropped (as the node's exact sync does) and counted in ``incomplete``.
    """

    def __init__(self, wanted: dict[str, tuple[str, str]], dynamic: Sequence[str]) -> None:
        self.wanted = wanted
        self.required = set(dynamic)
        self.incomplete = 0

    def steps(self, reader: Any) -> Iterator[Step]:
        from collres_ros import messages
        pending: dict[int, dict[str, dict[str, Any]]] = {}
        for m in reader.messages(list(self.wanted)):
            name, kind = self.wanted[m.topic]
            stamp = _stamp_ns(m.msg.header.stamp)
            group = pending.setdefault(stamp, {})
            group.setdefault(name, {})[kind] = m.msg
            complete = {n for n, parts in group.items() if len(parts) == 2}
            if not self.required <= complete:
                continue
            del pending[stamp]
            inputs = [messages.input_from_pose_twist(n, parts['pose'], parts['twist'])
                      for n, parts in sorted(group.items()) if len(parts) == 2]
            yield Step(stamp, m.log_time, inputs, True)
            for old in [s for s in pending if s < stamp]:
                del pending[old]
                self.incomplete += 1
        self.incomplete += len(pending)


def replay(in_bag: Path, out_bag: Path, params: Path, storage: str | None = None,
           namespace: str = '/', progress: Callable[[int, int], None] | None = None,
           topics: Sequence[str] | None = None, compress: bool = False) -> ReplaySummary:
    """Replay ``in_bag`` into a new ``out_bag``; ReplayError/BagError/ValueError on bad input.

    ``topics``: write only these output topics (relative names; default all).
    ``compress``: zstd mcap chunks (see ``BagWriter``).
    """
    from collres_ros import messages, params as params_module
    from collres_ros.bag import STORAGES, BagReader, BagWriter
    from collres_ros.core.pipeline import Resolver

    if storage is not None and storage not in STORAGES:
        raise ReplayError(f'unknown storage {storage!r} (supported: {", ".join(STORAGES)})')
    if not params.is_file():
        raise ReplayError(f'params file not found: {params}')
    scene = params_module.load_scene(params)
    summary = ReplaySummary()
    start = time.perf_counter()
    with BagReader(in_bag) as reader:
        if out_bag.exists():
            raise ReplayError(f'output bag already exists: {out_bag}')
        source, total = read_steps(reader, scene, namespace)
        resolver = Resolver(scene)
        with BagWriter(out_bag, storage or reader.storage, compress) as writer:
            for step in source.steps(reader):
                resolved = resolver.resolve(step.stamp, step.inputs)
                outputs = messages.build_outputs(resolved, scene.world_frame,
                                                 per_body=step.per_body)
                for topic, msg in outputs:
                    if topics is None or topic in topics:
                        writer.write(topic_name(topic, namespace) if not topic.startswith('/')
                                     else topic, step.log_time, msg)
                    if topic == 'contacts':
                        for contact in msg.contacts:
                            key = STATE_NAMES.get(contact.state, str(contact.state))
                            summary.contacts[key] = summary.contacts.get(key, 0) + 1
                for rejection in _rejections(resolved):
                    summary.rejected[rejection.reason] = \
                        summary.rejected.get(rejection.reason, 0) + 1
                summary.messages_in += len(step.inputs) * 2 if step.per_body else 1
                summary.steps += 1
                if progress is not None:
                    progress(summary.steps, total)
            summary.messages_out = writer.count
        summary.incomplete = source.incomplete
    summary.wall_s = time.perf_counter() - start
    return summary


def _rejections(resolved: Any) -> list[Any]:
    for name in ('rejected', 'rejections'):
        value = getattr(resolved, name, None)
        if value is not None:
            return list(value)
    return []


def _progress_printer() -> Callable[[int, int], None]:
    """Progress on stderr, at most twice a second."""
    last = [0.0]

    def show(done: int, total: int) -> None:
        now = time.monotonic()
        if done == total or now - last[0] >= 0.5:
            last[0] = now
            percent = 100.0 * done / total if total else 100.0
            print(f'\rreplay: {done}/{total} steps ({percent:.0f} %)', end='',
                  file=sys.stderr, flush=True)
            if done == total:
                print(file=sys.stderr)
    return show


def parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog='collres_replay',
        description='Run a recorded rosbag2 bag through the collres core offline and write '
                    'every output topic of collres_node to a new bag.')
    p.add_argument('in_bag', help='input bag directory (mcap or sqlite3)')
    p.add_argument('out_bag', help='output bag directory (must not exist)')
    p.add_argument('--params', required=True, help='params file of the scene (as the node)')
    p.add_argument('--storage', help='output storage: mcap or sqlite3 (default: as the input)')
    p.add_argument('--namespace', default='/', help='namespace of the node\'s topics (/)')
    p.add_argument('--quiet', action='store_true', help='no progress on stderr')
    return p


def main(argv: Sequence[str] | None = None) -> int:
    args = parser().parse_args(argv)
    from collres_ros.bag import BagError
    try:
        summary = replay(Path(args.in_bag), Path(args.out_bag), Path(args.params),
                         args.storage, args.namespace,
                         None if args.quiet else _progress_printer())
    except (ReplayError, BagError, ValueError, OSError) as error:
        print(f'error: {error}', file=sys.stderr)
        return 1
    print(f'wrote {args.out_bag}')
    for line in summary.lines():
        print(line)
    return 0


if __name__ == '__main__':
    sys.exit(main())
