"""Offline stepping and recording: the core in-process, inputs and outputs in rosbag2 bags.

Two roads, one output builder (``messages.build_outputs``, the node's own):

* ``run_offline``: the simulator's scene (``ros.simulation``) stepped through
  the core without DDS, as fast as it can, recorded (inputs and every output)
  into a new bag; used by ``collres_sim --offline`` and to make the goldens.
* ``replay``: a recorded bag's inputs (batched ``body_states``, or per-body
  pose/twist grouped by the node's ``StampSync``) through the core, every
  output written to a new bag at the input's log time; ``collres_replay``.

Deterministic: the same input gives the same output messages.
"""

from __future__ import annotations

import shutil
import time
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Iterator, Mapping, Sequence

from collres_ros.ros.cli import CliError
from collres_ros.ros.diagnostics import OfflineDiagnostics
from collres_ros.ros.names import STATE_NAMES, STATES, absolute, output_topics, state_name
from collres_ros.ros.simulation import SimScene, rows_of, run_loop
from collres_ros.ros.stamps import seconds_ns


class ReplayError(CliError):
    """A user error of a replay: one line, printed as ``error: ...``."""


def count_states(counts: dict[str, int], states: Any) -> None:
    """Add a step's contact states (Contact.state values) to ``counts`` by name."""
    for value in states:
        key = state_name(value)
        counts[key] = counts.get(key, 0) + 1


# --- the simulator's scene, offline -----------------------------------------------------------

@dataclass
class OfflineSummary:
    """What an offline run recorded: steps, bag messages, contacts by state, wall time (s)."""

    steps: int
    messages: int
    contacts: dict[str, int]
    wall_s: float


def run_core(sim: SimScene, sink: Callable[[int, list[tuple[str, Any]]], None],
             on_step: Callable[[int, int], None] | None = None, markers: bool = True,
             contacts: dict[str, int] | None = None) -> int:
    """Run the scene through the core in-process; returns the number of steps.

    ``sink(stamp_ns, [(topic, wire type, CDR bytes), ...])`` gets, per step,
    the ``body_states`` input followed by every output of the node's encoder
    (relative topic names, as the node publishes them). ``markers`` False skips
    building contact_markers and body_markers (they dominate the cost with many contacts).
    ``contacts``: counts of the solved contacts by state, added to.
    """
    from collres_ros.core.pipeline import Resolver
    from collres_ros.core.types import InputBatch
    from collres_ros.ros import messages
    resolver = Resolver.for_scene(sim.scene)
    node = sim.scene.node
    diagnostics = OfflineDiagnostics(node.diagnostics_period)
    encoder = messages.OutputEncoder(sim.names, sim.world_frame, sim.scene.bodies)
    names = [sim.names[i] for i in sim.rows]

    def exchange(stamp: int, states: Any) -> Any:
        values = messages.state_values(rows_of(states, sim.rows))
        step = resolver.resolve(stamp, InputBatch(names, values, sim.world_frame,
                                                  sim.world_frame))
        outputs = encoder.encode(step, per_body=False, marker_lifetime=node.marker_lifetime,
                                 diagnostics=diagnostics.update(step, resolver),
                                 markers=markers, wrenches=node.contact_wrench,
                                 body_markers=node.body_markers_period if markers else None,
                                 tf=node.publish_tf)
        state = encoder.states.encode(stamp, sim.world_frame, names, values)
        sink(stamp, [(STATES, messages.TYPES[STATES], state)] + outputs)
        if contacts is not None:
            count_states(contacts, step.report.state)
        return step.names, step.states

    steps, _ = run_loop(sim, exchange, on_step)
    return steps


def run_offline(sim: SimScene, record: Path, storage: str = 'mcap', progress: bool = False,
                topics: Sequence[str] | None = None, compress: bool = False) -> OfflineSummary:
    """Step the scene in-process and record input and outputs to a new bag.

    ``progress``: a progress line on stderr, when stdout and stderr are terminals.
    Topics are recorded in the scene's namespace (``sim.namespace``).
    ``topics``: record only these (relative names; default: all). ``compress``:
    zstd mcap chunks.
    """
    from collres_ros.ros import qos
    from collres_ros.ros.bag import BagWriter, describe
    from collres_ros.ros.console import progress_printer
    contacts: dict[str, int] = {}
    start = time.perf_counter()

    show = progress_printer('collres_sim') if progress else None   # on a terminal only
    depth = sim.scene.node.queue_depth
    with BagWriter(record, storage, compress, qos=lambda topic: [qos.offered(topic, depth)],
                   custom_data=describe(sim.scene)) as writer:
        def sink(stamp: int, outputs: list[tuple[str, str, bytes]]) -> None:
            for topic, kind, data in outputs:
                if topics is None or topic in topics:
                    writer.write_raw(absolute(topic, sim.namespace), kind, stamp, data)

        steps = run_core(sim, sink, show,
                         markers=topics is None or 'contact_markers' in topics
                         or 'body_markers' in topics, contacts=contacts)
        messages = writer.count
    return OfflineSummary(steps, messages, contacts, time.perf_counter() - start)


# --- a recorded bag, replayed -----------------------------------------------------------------

@dataclass
class Step:
    """One resolution step read from the input bag."""

    stamp: int          # ns, header stamp of the inputs
    log_time: int       # ns, receive time of the message that completed the step
    inputs: Any         # InputBatch (or BodyInput list) for Resolver.resolve
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
    served: int = 0         # bodies served (accepted inputs), all steps

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


class BatchedSource:
    """One step per body_states message."""

    def __init__(self, topic: str, max_bodies: int) -> None:
        from collres_ros.ros.codec import StatesCodec
        self.topic = topic
        self.incomplete = 0
        self.refused: Counter[str] = Counter()    # messages the codec refused, by reason
        self.codec = StatesCodec(max_bodies)
        self.read: dict[str, int] = {topic: 0}   # messages read, by topic

    def steps(self, reader: Any) -> Iterator[Step]:
        from collres_ros.core.types import InputBatch
        from collres_ros.ros.codec import DecodeError
        for _, _, log_time, data in reader.raw([self.topic]):
            self.read[self.topic] += 1
            try:
                d = self.codec.decode(data)
            except DecodeError as refusal:
                self.refused[refusal.reason] += 1
                continue
            yield Step(d.stamp_ns, log_time, InputBatch(d.names, d.values, d.frame_id,
                                                        d.frame_id), False)


def read_steps(reader: Any, scene: Any, namespace: str) -> tuple[Any, int]:
    """Return a step source (``.steps(reader)``, ``.incomplete``) and the step count.

    Batched if the bag has body_states, else per body.

    ReplayError when the bag has none of the input topics.
    """
    topics = reader.topics
    batched = absolute(STATES, namespace)
    if batched in topics:
        _check_type(reader, batched, BATCHED_TYPE)
        return BatchedSource(batched, len(scene.bodies)), reader.topic_count(batched)
    wanted = {}
    for body in scene.bodies:
        for kind in ('pose', 'twist'):
            name = absolute(f'bodies/{body.name}/{kind}', namespace)
            if name in topics:
                _check_type(reader, name, PART_TYPES[kind])
                wanted[name] = (body.name, kind)
    if not wanted:
        raise ReplayError(f'no input topics in {reader.path}: expected {batched} or '
                          f'{absolute("bodies/<name>/pose", namespace)} and .../twist '
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
        # a per-body step's bodies, in the scene's order (``messages.batch_from_group``)
        self._body_order = tuple(b.name for b in scene.bodies)
        self._dynamic_names = frozenset(self.dynamic)
        node = scene.node
        self.sync = StampSync(self.dynamic, [b.name for b in scene.bodies if b.static],
                              seconds_ns(node.sync_slop), seconds_ns(node.stale_timeout))
        self.incomplete = 0
        self.refused: Counter[str] = Counter()    # messages the codec refused, by reason
        self.read: dict[str, int] = {topic: 0 for topic in wanted}

    @property
    def sync_dropped(self) -> int:
        return int(self.sync.dropped)

    def steps(self, reader: Any) -> Iterator[Step]:
        from collres_ros.ros import messages
        from collres_ros.ros.codec import DecodeError, decode_pose, decode_twist
        for topic, _, log_time, data in reader.raw(list(self.wanted)):
            self.read[topic] += 1
            name, kind = self.wanted[topic]
            try:
                part = decode_pose(data) if kind == 'pose' else decode_twist(data)
            except DecodeError as refusal:
                self.refused[refusal.reason] += 1
                continue
            for group in self.sync.add(name, kind, part.stamp_ns, part):
                yield Step(group.stamp_ns, log_time,
                           messages.batch_from_group(group.parts, self._dynamic_names,
                                                     self._body_order), True)
        self.incomplete = self.sync.dropped + len(self.sync.pending)


def replay(in_bag: Path, out_bag: Path, params: Path | None, storage: str | None = None,
           namespace: str = '/', progress: Callable[[int, int], None] | None = None,
           topics: Sequence[str] | None = None, compress: bool = False,
           overrides: Mapping[str, Any] | None = None) -> ReplaySummary:
    """Replay ``in_bag`` into a new ``out_bag``; ReplayError/BagError/ValueError on bad input.

    ``params``: the scene's params file; None: the params recorded in the bag
    (custom_data ``collres_ros.params``, written by collres_sim, collres_replay
    and collres_demo).

    ``topics``: write only these output topics (relative names; default all).
    ``compress``: zstd mcap chunks (see ``BagWriter``). ``overrides``: values that win over
    the params file's (collres_replay: the URDF a robot_description_topic scene waited for).
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
        scene = _scene(params, reader, namespace, overrides)
        unknown = [t for t in topics or () if t not in output_topics(scene.names)]
        if unknown:
            raise ReplayError(f'--topics: not an output topic: '
                              f'{", ".join(repr(t[:80]) for t in unknown[:5])} (outputs: '
                              f'{", ".join(output_topics([]))}, bodies/<name>/pose/corrected, '
                              'bodies/<name>/twist/corrected, bodies/<name>/contact_wrench)')
        if topics is not None and not topics:
            raise ReplayError('--topics: no topic given')
        if out_bag.exists():
            raise ReplayError(f'output bag already exists: {out_bag}')
        source, total = read_steps(reader, scene, namespace)
        resolver = Resolver.for_scene(scene)
        diagnostics = OfflineDiagnostics(scene.node.diagnostics_period)
        encoder = messages.OutputEncoder(scene.names, scene.world_frame, scene.bodies)
        depth = scene.node.queue_depth
        try:
            with BagWriter(out_bag, storage or reader.storage, compress,
                           qos=lambda topic: [qos.offered(topic, depth)],
                           custom_data=describe(scene)) as writer:
                for step in _readable(source.steps(reader), in_bag):
                    resolved = resolver.resolve(step.stamp, step.inputs)
                    outputs = encoder.encode(
                        resolved, per_body=step.per_body and scene.node.per_body_outputs,
                        marker_lifetime=scene.node.marker_lifetime,
                        diagnostics=diagnostics.update(resolved, resolver,
                                                       getattr(source, 'sync_dropped', 0)),
                        markers=topics is None or 'contact_markers' in topics,
                        wrenches=scene.node.contact_wrench,
                        body_markers=scene.node.body_markers_period
                        if topics is None or 'body_markers' in topics else None,
                        tf=scene.node.publish_tf)
                    for topic, kind, data in outputs:
                        if topics is None or topic in topics:
                            writer.write_raw(absolute(topic, namespace), kind, step.log_time,
                                             data)
                    count_states(summary.contacts, resolved.report.state)
                    for rejection in _rejections(resolved):
                        summary.rejected[rejection.reason] = \
                            summary.rejected.get(rejection.reason, 0) + 1
                    summary.messages_in += len(step.inputs) * 2 if step.per_body else 1
                    summary.steps += 1
                    summary.served += len(resolved.names)
                    if progress is not None:
                        progress(summary.steps, total)
                summary.messages_out = writer.count
                for reason, count in source.refused.items():
                    summary.rejected[reason] = summary.rejected.get(reason, 0) + count
                _check_complete(reader, source, in_bag)
                _check_resolved(summary, in_bag)
        except BaseException:
            # a failed run leaves no output behind (a rerun must not meet "already exists")
            shutil.rmtree(out_bag, ignore_errors=True)
            raise
        summary.incomplete = source.incomplete
    summary.wall_s = time.perf_counter() - start
    return summary


BATCHED_TYPE = 'collres_ros/msg/BodyStateArray'
PART_TYPES = {'pose': 'geometry_msgs/msg/PoseStamped', 'twist': 'geometry_msgs/msg/TwistStamped'}


def _check_type(reader: Any, topic: str, expected: str) -> None:
    """ReplayError when an input topic of the bag has another message type."""
    found = reader.topics.get(topic)
    if found != expected:
        raise ReplayError(f'{reader.path}: topic {topic} has type {found}, expected {expected}')


def _readable(steps: Iterator[Step], path: Path) -> Iterator[Step]:
    """The steps, with any failure of reading or decoding the bag as one ReplayError."""
    while True:
        try:
            step = next(steps)
        except StopIteration:
            return
        except (ReplayError, KeyboardInterrupt):
            raise
        except Exception as error:   # rosbags, mcap, zstd and CDR errors: a damaged bag
            text = (str(error).strip().splitlines() or [''])[0][:200]
            raise ReplayError(f'{path}: unreadable part of the bag '
                              f'({type(error).__name__}: {text})') from None
        yield step


def _check_complete(reader: Any, source: Any, path: Path) -> None:
    """ReplayError when fewer input messages were read than the bag's metadata counts."""
    for topic, read in sorted(getattr(source, 'read', {}).items()):
        expected = reader.topic_count(topic)
        if read < expected:
            raise ReplayError(f'{path}: read {read} of the {expected} messages of {topic}: '
                              'the bag is damaged (part of its data is unreadable)')


def _check_resolved(summary: ReplaySummary, path: Path) -> None:
    """ReplayError when the run resolved nothing (no step, or every input refused)."""
    if summary.steps == 0:
        raise ReplayError(f'nothing resolved: no complete step in {path}')
    if summary.served == 0:
        reasons = ', '.join(f'{k} {v}' for k, v in sorted(summary.rejected.items()))
        raise ReplayError(f'nothing resolved: every input was refused ({reasons}); '
                          'is --params the scene of this bag?')


def _scene(params: Path | None, reader: Any, namespace: str,
           overrides: Mapping[str, Any] | None = None) -> Any:
    """The scene of ``params`` (with ``overrides``), or else the params recorded in the bag's
    custom_data."""
    from collres_ros.ros import params as params_module
    from collres_ros.ros.bag import PARAMS_KEY
    if params is not None:
        return params_module.load_scene(params, namespace, overrides)
    text = reader.custom_data.get(PARAMS_KEY)
    if text is None or text == '':
        raise ReplayError(f'{reader.path} carries no params (custom_data {PARAMS_KEY}): '
                          'give --params FILE')
    return params_module.load_recorded_scene(text, f'{reader.path} ({PARAMS_KEY})', namespace)


def _rejections(resolved: Any) -> list[Any]:
    for name in ('rejected', 'rejections'):
        value = getattr(resolved, name, None)
        if value is not None:
            return list(value)
    return []
