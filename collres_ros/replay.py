"""collres_replay: run a recorded rosbag2 bag through the core offline, deterministically.

::

    collres_replay IN_BAG OUT_BAG [--params FILE] [--storage mcap|sqlite3] [--namespace NS]

Reads the node's input topics from IN_BAG (mcap or sqlite3): the batched
``body_states`` (one step per message), or else the per-body
``bodies/<name>/pose`` + ``bodies/<name>/twist``, grouped by header stamp (a
step when every dynamic body of the scene has both for the same stamp, as the
node's exact sync does). Every step goes through the same ``Resolver`` and the
same output builder as ``collres_node``, and every output topic is written to
OUT_BAG at the log time of the input message that completed the step (the
node publishes its answer on receipt). Progress goes to stderr (on a terminal
only), a summary to stdout; errors exit 1 with one ``error: ...`` line.

Same input, same output: the core is deterministic, so two replays of a bag
give identical decoded messages.
"""

from __future__ import annotations

import argparse
import os
import struct
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


class OfflineDiagnostics:
    """/diagnostics of an offline run, as collres_node reports them, on the stamps' clock.

    A snapshot every ``period`` s of stamp time (the node's
    ``diagnostics_period``) with the node's fields: steps, rate (steps per
    second of stamp time here), contacts of the last step, the resolver's
    totals by reason, stale bodies, and the extras (bodies, sync_dropped,
    contacts_total). Step times are wall-clock figures: reported only with
    ``timings=True``, otherwise 0, so that a replay is deterministic.
    """

    def __init__(self, period: float, timings: bool = False) -> None:
        self.period_ns = int(round(period * 1e9))
        self.timings = timings
        self.steps = 0
        self._last_ns: int | None = None
        self._steps_at_last = 0
        self._times: list[float] = []

    def update(self, resolved: Any, resolver: Any, sync_dropped: int = 0) -> Any | None:
        """Account for one ResolvedStep; a DiagnosticsSnapshot when one is due, else None."""
        from collres_ros.ros.messages import DiagnosticsSnapshot
        self.steps += 1
        self._times.append(float(getattr(resolved, 'step_time_s', 0.0)))
        stamp = int(resolved.stamp_ns)
        if self._last_ns is None:
            self._last_ns = stamp
        elapsed = stamp - self._last_ns
        if elapsed < self.period_ns and self.steps > 1:
            return None
        rate = (self.steps - self._steps_at_last) / (elapsed * 1e-9) if elapsed > 0 else 0.0
        times = self._times if self.timings else [0.0]
        totals = resolver.totals
        snapshot = DiagnosticsSnapshot(
            stamp_ns=stamp, steps=int(totals.get('steps', self.steps)), rate_hz=rate,
            step_time_mean_ms=1000.0 * sum(times) / len(times),
            step_time_max_ms=1000.0 * max(times), contacts=int(resolved.report.contacts.count),
            counts={k: v for k, v in totals.items() if k not in ('steps', 'contacts')},
            stale=sorted(getattr(resolved, 'stale', [])),
            extra={'bodies': len(resolver.bodies), 'sync_dropped': sync_dropped,
                   'contacts_total': int(totals.get('contacts', 0))})
        self._last_ns, self._steps_at_last, self._times = stamp, self.steps, []
        return snapshot


def topic_name(relative: str, namespace: str) -> str:
    """Absolute topic of a relative name in ``namespace`` ('/' or '/robot')."""
    return namespace.rstrip('/') + '/' + relative


def _stamp_ns(stamp: Any) -> int:
    return int(stamp.sec) * 10**9 + int(stamp.nanosec)


_LE_CDR = b'\x00\x01'  # encapsulation kind: plain CDR, little endian
_STATE = struct.Struct('<13d')  # pose (position 3, orientation 4), twist (linear 3, angular 3)


def decode_body_state_array(data: bytes) -> tuple[int, list[Any]] | None:
    """(stamp ns, BodyInputs) of a serialized BodyStateArray, or None if not plain LE CDR.

    The fast path of replay (rclpy's deserialize_message builds ~10 Python
    objects per body: ~80 us per body). Same result as
    ``messages.inputs_from_array(deserialize_message(data, BodyStateArray))``
    (a test checks it); anything unexpected falls back to that.
    """
    from collres_ros.core.types import BodyInput
    if data[:2] != _LE_CDR:
        return None
    buf = memoryview(data)[4:]   # alignment is relative to the end of the encapsulation

    def string(offset: int) -> tuple[str, int]:
        offset += -offset % 4
        (length,) = struct.unpack_from('<I', buf, offset)
        text = bytes(buf[offset + 4:offset + 4 + max(length - 1, 0)]).decode()
        return text, offset + 4 + length

    sec, nanosec = struct.unpack_from('<iI', buf, 0)
    frame, offset = string(8)
    offset += -offset % 4
    (count,) = struct.unpack_from('<I', buf, offset)
    offset += 4
    inputs = []
    for _ in range(count):
        name, offset = string(offset)
        offset += -offset % 8
        v = _STATE.unpack_from(buf, offset)
        offset += _STATE.size
        inputs.append(BodyInput(name, v[0:3], v[3:7], v[7:10], v[10:13], frame, frame))
    if offset > len(buf):
        return None
    return sec * 1_000_000_000 + nanosec, inputs


class BatchedSource:
    """One step per body_states message."""

    def __init__(self, topic: str) -> None:
        self.topic = topic
        self.incomplete = 0

    def steps(self, reader: Any) -> Iterator[Step]:
        from rclpy.serialization import deserialize_message

        from collres_ros.ros import messages
        from collres_ros.msg import BodyStateArray
        for _, _, log_time, data in reader.raw([self.topic]):
            try:
                decoded = decode_body_state_array(data)
            except (struct.error, UnicodeDecodeError):
                decoded = None
            if decoded is None:
                msg = deserialize_message(data, BodyStateArray)
                decoded = _stamp_ns(msg.header.stamp), messages.inputs_from_array(msg)
            yield Step(decoded[0], log_time, decoded[1], False)


def read_steps(reader: Any, scene: Any, namespace: str) -> tuple[Any, int]:
    """Return a step source (``.steps(reader)``, ``.incomplete``) and the step count.

    Batched if the bag has body_states, else per body.

    ReplayError when the bag has none of the input topics.
    """
    topics = reader.topics
    batched = topic_name('body_states', namespace)
    if batched in topics:
        return BatchedSource(batched), reader.topic_count(batched)
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
    grouper = PerBodyGrouper(wanted, scene)
    return grouper, min(reader.topic_count(t) for t in wanted)


class PerBodyGrouper:
    """Per-body pose/twist messages grouped into steps by the node's own ``StampSync``.

    Same rules as collres_node: a step once every (non-stale) dynamic body
    has a pose and a twist for the stamp (within ``sync_slop``); static bodies
    join with their pose (twist optional); groups overtaken by a newer
    complete one are dropped and counted in ``incomplete``.
    """

    def __init__(self, wanted: dict[str, tuple[str, str]], scene: Any) -> None:
        from collres_ros.ros.sync import StampSync
        self.wanted = wanted
        self.dynamic = [b.name for b in scene.bodies if not b.static]
        node = scene.node
        self.sync = StampSync(self.dynamic, [b.name for b in scene.bodies if b.static],
                              int(round(node.sync_slop * 1e9)),
                              int(round(node.stale_timeout * 1e9)))
        self.incomplete = 0

    @property
    def sync_dropped(self) -> int:
        return int(self.sync.dropped)

    def steps(self, reader: Any) -> Iterator[Step]:
        from collres_ros.ros import messages
        for m in reader.messages(list(self.wanted)):
            name, kind = self.wanted[m.topic]
            for group in self.sync.add(name, kind, _stamp_ns(m.msg.header.stamp), m.msg):
                yield Step(group.stamp_ns, m.log_time,
                           messages.inputs_from_group(group.parts, self.dynamic), True)
        self.incomplete = self.sync.dropped + len(self.sync.pending)


def replay(in_bag: Path, out_bag: Path, params: Path | None, storage: str | None = None,
           namespace: str = '/', progress: Callable[[int, int], None] | None = None,
           topics: Sequence[str] | None = None, compress: bool = False) -> ReplaySummary:
    """Replay ``in_bag`` into a new ``out_bag``; ReplayError/BagError/ValueError on bad input.

    ``params``: the scene's params file; None: the params recorded in the bag
    (custom_data ``collres_ros.params``, written by collres_sim, collres_replay
    and collres_demo).

    ``topics``: write only these output topics (relative names; default all).
    ``compress``: zstd mcap chunks (see ``BagWriter``).
    """
    from collres_ros.ros import messages, qos
    from collres_ros.ros.bag import STORAGES, BagReader, BagWriter, describe
    from collres_ros.core.pipeline import Resolver

    if storage is not None and storage not in STORAGES:
        raise ReplayError(f'unknown storage {storage!r} (supported: {", ".join(STORAGES)})')
    if params is not None and not params.is_file():
        raise ReplayError(f'params file not found: {params}')
    summary = ReplaySummary()
    start = time.perf_counter()
    with BagReader(in_bag) as reader:
        scene = _scene(params, reader, namespace)
        if out_bag.exists():
            raise ReplayError(f'output bag already exists: {out_bag}')
        source, total = read_steps(reader, scene, namespace)
        resolver = Resolver(scene)
        diagnostics = OfflineDiagnostics(scene.node.diagnostics_period)
        depth = scene.node.queue_depth
        with BagWriter(out_bag, storage or reader.storage, compress,
                       qos=lambda topic: [qos.offered(topic, depth)],
                       custom_data=describe(scene)) as writer:
            for step in source.steps(reader):
                resolved = resolver.resolve(step.stamp, step.inputs)
                outputs = messages.build_outputs(
                    resolved, scene.world_frame,
                    per_body=step.per_body and scene.node.per_body_outputs,
                    marker_lifetime=scene.node.marker_lifetime,
                    diagnostics=diagnostics.update(resolved, resolver,
                                                   getattr(source, 'sync_dropped', 0)),
                    markers=topics is None or 'contact_markers' in topics)
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


def _scene(params: Path | None, reader: Any, namespace: str) -> Any:
    """The scene of ``params``, or else the params recorded in the bag's custom_data."""
    import tempfile

    from collres_ros.ros import params as params_module
    from collres_ros.ros.bag import PARAMS_KEY
    if params is not None:
        return params_module.load_scene(params, namespace)
    text = reader.custom_data.get(PARAMS_KEY)
    if not text:
        raise ReplayError(f'{reader.path} carries no params (custom_data {PARAMS_KEY}): '
                          'give --params FILE')
    with tempfile.TemporaryDirectory(prefix='collres_replay-') as scratch:
        path = Path(scratch) / 'params.yaml'
        path.write_text(text)
        return params_module.load_scene(path, namespace)


def _rejections(resolved: Any) -> list[Any]:
    for name in ('rejected', 'rejections'):
        value = getattr(resolved, name, None)
        if value is not None:
            return list(value)
    return []


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
    p.add_argument('--quiet', action='store_true',
                   help='no progress line (it is drawn on a terminal only anyway)')
    return p


def main(argv: Sequence[str] | None = None) -> int:
    args = parser().parse_args(argv)
    from collres_ros.ros.bag import BagError
    try:
        topics = None if args.topics is None else \
            tuple(t.strip() for t in args.topics.split(',') if t.strip())
        summary = replay(Path(args.in_bag), Path(args.out_bag),
                         Path(args.params) if args.params else None,
                         args.storage, args.namespace,
                         None if args.quiet else _progress_printer(), topics)
    except (ReplayError, BagError, ValueError, OSError) as error:
        print(f'error: {error}', file=sys.stderr)
        return 1
    try:
        print(f'wrote {args.out_bag}')
        for line in summary.lines():
            print(line)
        sys.stdout.flush()
    except BrokenPipeError:  # e.g. piped into head: the bag is written, that is what counts
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
    return 0


if __name__ == '__main__':
    sys.exit(main())
