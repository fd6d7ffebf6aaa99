"""rosbag2 reading and writing (mcap or sqlite3 storage) with rclpy messages.

No rosbag2_py exists for these wheels, so the bag container is handled by
``rosbags`` while the payload is always rclpy's own CDR: messages are written
as ``rclpy.serialization.serialize_message`` bytes (the bytes the node
publishes) and read back with ``deserialize_message`` into rclpy classes.

Every connection embeds its message definition (our ``collres_ros/msg/*``
types are registered from the ``.msg`` text next to the std types of the
Jazzy typestore), so the bags open with ``ros2 bag info/play`` on a ROS
install, with ``rosbags``, and (mcap) with the ``mcap`` + ``mcap_ros2``
readers. Timestamps are receive (log) times in ns since the epoch.

rclpy leaves CDR padding bytes uninitialised: compare decoded fields, never
raw bytes.
"""

from __future__ import annotations

import importlib
import signal
import threading
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path
from types import TracebackType
from typing import Any, Callable, Iterable, Iterator, Mapping, Sequence

from rosbags.rosbag2 import Reader, Writer
from rosbags.rosbag2.enums import CompressionFormat, CompressionMode, StoragePlugin
from rosbags.typesys import Stores, get_types_from_msg, get_typestore
from rosbags.typesys.store import Typestore

from collres_ros.ros.resources import MESSAGE_NAMES, message_definition

STORAGES = ('mcap', 'sqlite3')
PACKAGE = 'collres_ros'
_PLUGINS = {'mcap': StoragePlugin.MCAP, 'sqlite3': StoragePlugin.SQLITE3}
BAG_VERSION = 9  # rosbag2 metadata version written by Jazzy
STATES_TYPE = f'{PACKAGE}/msg/BodyStateArray'
CONTACTS_TYPE = f'{PACKAGE}/msg/ContactArray'


class BagError(Exception):
    """A bag cannot be opened, read or written; the message is one line for users."""


# Ctrl-C and SIGTERM (``cli.terminate_as_interrupt``) raise KeyboardInterrupt between two
# bytecodes, also inside the bag library's write of a chunk (a chunk half written, then
# the bag closed after it: "chunk ... cannot be read" when sealed). Their Python handlers
# are wrapped when a bag is opened (transparent outside a write) so that while a record
# is written they are only noted, and run once it is whole.
_INTERRUPTS = (signal.SIGINT, signal.SIGTERM)


class _Deferred:
    """A signal's Python handler that waits while a record is written (``_whole_records``)."""

    depth = 0                          # open _whole_records blocks (main thread)
    came: list[tuple[Callable[..., Any], int, Any]] = []   # signals noted in them

    def __init__(self, handler: Callable[..., Any]) -> None:
        self.handler = handler

    def __call__(self, signum: int, frame: Any) -> None:
        if _Deferred.depth:
            _Deferred.came.append((self.handler, signum, frame))
        else:
            self.handler(signum, frame)


def _defer_interrupts() -> None:
    """Wrap the Python handlers of Ctrl-C and SIGTERM in ``_Deferred`` (main thread only:
    Python runs signal handlers there, so nothing interrupts a write on another thread)."""
    if threading.get_ident() != _WholeRecords.main:
        return
    for number in _INTERRUPTS:
        handler = signal.getsignal(number)
        if callable(handler) and not isinstance(handler, _Deferred):
            signal.signal(number, _Deferred(handler))


class _WholeRecords:
    """Ctrl-C and SIGTERM (as wrapped when the bag opened) handled after the block, on the
    main thread (on another one nothing interrupts it)."""

    main = threading.main_thread().ident

    def __enter__(self) -> None:
        if threading.get_ident() == self.main:
            _Deferred.depth += 1

    def __exit__(self, *exc: object) -> None:
        if threading.get_ident() != self.main:
            return
        _Deferred.depth -= 1
        if not _Deferred.depth and _Deferred.came:
            handler, number, frame = _Deferred.came[0]
            _Deferred.came.clear()
            handler(number, frame)


_whole_records = _WholeRecords()


@lru_cache(maxsize=1)
def typestore() -> Typestore:
    """Return the Jazzy typestore with the ``collres_ros/msg/*`` types registered."""
    store = get_typestore(Stores.ROS2_JAZZY)
    types: dict[str, Any] = {}
    for name in MESSAGE_NAMES:
        types.update(get_types_from_msg(message_definition(name), f'{PACKAGE}/msg/{name}'))
    store.register(types)
    return store


def type_name(msg: Any) -> str:
    """Wire type name of an rclpy message instance or class, e.g. 'std_msgs/msg/Header'."""
    cls = msg if isinstance(msg, type) else type(msg)
    package = cls.__module__.split('.')[0]
    return f'{package}/msg/{cls.__name__}'


@lru_cache(maxsize=None)
def message_class(msgtype: str) -> type:
    """Return the rclpy class of a wire type name ('pkg/msg/Name'); BagError if unknown."""
    parts = msgtype.split('/')
    if len(parts) != 3:
        raise BagError(f'malformed message type {msgtype!r}')
    package, kind, name = parts
    try:
        return getattr(importlib.import_module(f'{package}.{kind}'), name)
    except (ImportError, AttributeError):
        raise BagError(f'message type {msgtype} is not available in this environment') from None


def storage_of(path: str | Path) -> str:
    """Storage id of an existing bag directory ('mcap' or 'sqlite3'); BagError otherwise."""
    path = Path(path)
    metadata = path / 'metadata.yaml'
    if not path.exists():
        raise BagError(f'bag not found: {path}')
    if not metadata.is_file():
        raise BagError(f'not a rosbag2 bag (no metadata.yaml): {path}')
    for line in metadata.read_text().splitlines():
        key, _, value = line.strip().partition(':')
        if key == 'storage_identifier':
            storage = value.strip().strip('\'"')
            if storage not in STORAGES:
                raise BagError(f'unknown storage {storage!r} in {path} '
                               f'(supported: {", ".join(STORAGES)})')
            return storage
    raise BagError(f'no storage_identifier in {metadata}')


@dataclass(frozen=True)
class BagMessage:
    """One message of a bag: topic, wire type, log time (ns) and the rclpy message."""

    topic: str
    msgtype: str
    log_time: int
    msg: Any


# custom_data keys of the bags collres_ros writes (metadata.yaml, rosbag2_bagfile_information)
VERSION_KEY = 'collres_ros.version'
PARAMS_KEY = 'collres_ros.params'


def describe(scene: Any) -> dict[str, str]:
    """custom_data of a bag recorded on ``scene``: the package version and the params.

    The params are a complete params file (every parameter, convex meshes
    inlined as points) that ``collres_replay`` reads when no ``--params`` is given.
    """
    from collres_ros import __version__
    from collres_ros.ros.params import scene_to_yaml
    return {VERSION_KEY: __version__, PARAMS_KEY: scene_to_yaml(scene)}


class BagWriter:
    """Write rclpy messages to a new rosbag2 bag; use as a context manager.

    Topics are added on first write from the message's class (or explicitly
    with ``add_topic``). ``path`` must not exist yet (rosbag2's rule).
    ``compress``: zstd-compressed mcap chunks (the mcap format's own chunk
    compression, read transparently by every mcap reader; mcap storage only).
    ``qos``: the rclpy QoS profiles offered on a topic (absolute name), written
    to ``offered_qos_profiles`` in metadata.yaml when the topic is added.
    ``custom_data``: string pairs for metadata.yaml's ``custom_data``.
    """

    def __init__(self, path: str | Path, storage: str = 'mcap', compress: bool = False,
                 qos: Callable[[str], Sequence[Any]] | None = None,
                 custom_data: Mapping[str, str] | None = None) -> None:
        if storage not in STORAGES:
            raise BagError(f'unknown storage {storage!r} (supported: {", ".join(STORAGES)})')
        self.path = Path(path)
        if self.path.exists():
            raise BagError(f'output bag already exists: {self.path}')
        self.storage = storage
        self._writer = Writer(self.path, version=BAG_VERSION, storage_plugin=_PLUGINS[storage])
        if compress:
            if storage != 'mcap':
                raise BagError('chunk compression needs mcap storage')
            self._writer.set_compression(CompressionMode.STORAGE, CompressionFormat.ZSTD)
        self._connections: dict[str, Any] = {}
        self._types: dict[str, str] = {}
        self._qos = qos
        for key, value in (custom_data or {}).items():
            self.set_custom_data(key, value)
        self.count = 0
        self._open = False

    def set_custom_data(self, key: str, value: str) -> None:
        """One ``custom_data`` entry of metadata.yaml (written when the bag closes)."""
        self._writer.set_custom_data(key, value)

    def open(self) -> 'BagWriter':
        self.path.parent.mkdir(parents=True, exist_ok=True)
        _defer_interrupts()
        self._writer.open()
        self._open = True
        return self

    def close(self) -> None:
        """Finish the bag: index, metadata.yaml and (mcap) every CRC (``mcap_crc.seal``)."""
        if self._open:
            self._open = False
            with _whole_records:
                self._writer.close()
                if self.storage == 'mcap':
                    from collres_ros.ros.mcap_crc import seal
                    for part in sorted(self.path.glob('*.mcap')):
                        seal(part)

    def discard(self) -> None:
        """Remove the bag being written (a bag that failed to write is not left behind)."""
        import shutil
        self._open = False
        shutil.rmtree(self.path, ignore_errors=True)

    def __enter__(self) -> 'BagWriter':
        return self.open()

    def __exit__(self, kind: type[BaseException] | None, value: BaseException | None,
                 traceback: TracebackType | None) -> None:
        """Finish the bag; an error (not an interrupt: Ctrl-C, SIGTERM) removes it."""
        if kind is not None and not issubclass(kind, (KeyboardInterrupt, SystemExit)):
            self.discard()
            return
        try:
            self.close()
        except BaseException:
            self.discard()
            raise

    def add_topic(self, topic: str, msgtype: str, qos: Sequence[Any] | None = None) -> None:
        """Declare a topic with its wire type (idempotent); BagError on a type clash.

        ``qos``: rclpy QoS profiles offered on it (default: from the writer's ``qos``).
        """
        known = self._types.get(topic)
        if known == msgtype:
            return
        if known is not None:
            raise BagError(f'topic {topic} already has type {known}, not {msgtype}')
        if qos is None and self._qos is not None:
            qos = self._qos(topic)
        from collres_ros.ros.qos import to_bag_list
        self._connections[topic] = self._writer.add_connection(
            topic, msgtype, typestore=typestore(), offered_qos_profiles=to_bag_list(qos or ()))
        self._types[topic] = msgtype

    def write(self, topic: str, log_time: int, msg: Any) -> None:
        """Write one rclpy message at ``log_time`` (ns)."""
        from rclpy.serialization import serialize_message
        self.write_raw(topic, type_name(msg), log_time, serialize_message(msg))

    def write_raw(self, topic: str, msgtype: str, log_time: int, data: bytes) -> None:
        """Write CDR bytes (as rclpy publishes them) at ``log_time`` (ns)."""
        self.add_topic(topic, msgtype)
        with _whole_records:
            self._writer.write(self._connections[topic], int(log_time), data)
        self.count += 1


class BagReader:
    """Read a rosbag2 bag (mcap or sqlite3) into rclpy messages; a context manager."""

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        self.storage = storage_of(self.path)
        try:
            self._reader = Reader(self.path)
        except Exception as error:  # rosbags raises several types for a bad bag
            raise BagError(f'cannot open bag {self.path}: {error}') from None
        self._open = False

    def open(self) -> 'BagReader':
        """Open the bag; an mcap file whose CRCs do not match is refused (BagError)."""
        if self.storage == 'mcap':
            from collres_ros.ros.mcap_crc import CrcError, check
            for part in sorted(self.path.glob('*.mcap')):
                try:
                    check(part)
                except (CrcError, OSError) as error:
                    raise BagError(f'{self.path}: damaged bag, {part.name}: {error}') from None
        try:
            self._reader.open()
        except Exception as error:
            raise BagError(f'cannot open bag {self.path}: {error}') from None
        self._open = True
        return self

    def close(self) -> None:
        if self._open:
            self._reader.close()
            self._open = False

    def __enter__(self) -> 'BagReader':
        return self.open()

    def __exit__(self, kind: type[BaseException] | None, value: BaseException | None,
                 traceback: TracebackType | None) -> None:
        self.close()

    @property
    def topics(self) -> dict[str, str]:
        """Topic name -> wire type of every topic in the bag."""
        return {c.topic: c.msgtype for c in self._reader.connections}

    @property
    def metadata(self) -> dict[str, Any]:
        """``rosbag2_bagfile_information`` of metadata.yaml, as plain YAML values."""
        from collres_ros.ros.params_yaml import plain_document
        path = self.path / 'metadata.yaml'
        try:
            document = plain_document(path.read_text(), str(path))
            return dict(document['rosbag2_bagfile_information'])
        except (OSError, ValueError, KeyError, TypeError) as error:
            raise BagError(f'cannot read {path}: {error}') from None

    @property
    def custom_data(self) -> dict[str, Any]:
        """metadata.yaml's ``custom_data`` (empty when the bag has none; values as written)."""
        custom = self.metadata.get('custom_data') or {}
        if not isinstance(custom, dict):
            raise BagError(f'{self.path / "metadata.yaml"}: custom_data must be a mapping '
                           f'(got a {type(custom).__name__})')
        return dict(custom)

    def offered_qos(self, topic: str) -> list[dict[str, Any]]:
        """The ``offered_qos_profiles`` recorded for ``topic`` (YAML dicts; [] if none)."""
        for entry in self.metadata.get('topics_with_message_count') or []:
            meta = entry.get('topic_metadata', {})
            if meta.get('name') == topic:
                value = meta.get('offered_qos_profiles') or []
                if isinstance(value, str):   # metadata version 8 and older: YAML text
                    import yaml
                    value = yaml.safe_load(value) or []
                return list(value)
        return []

    @property
    def message_count(self) -> int:
        return int(self._reader.message_count)

    def topic_count(self, topic: str) -> int:
        return sum(c.msgcount for c in self._reader.connections if c.topic == topic)

    def raw(self, topics: Iterable[str] | None = None) -> Iterator[tuple[str, str, int, bytes]]:
        """(topic, msgtype, log_time ns, CDR bytes) in log-time order."""
        for _, topic, msgtype, log_time, data in self._raw(topics):
            yield topic, msgtype, log_time, data

    def _raw(self, topics: Iterable[str] | None
             ) -> Iterator[tuple[Any, str, str, int, bytes]]:
        wanted = None if topics is None else set(topics)
        connections = [c for c in self._reader.connections
                       if wanted is None or c.topic in wanted]
        if not connections:
            return
        for connection, log_time, data in self._reader.messages(connections=connections):
            yield connection, connection.topic, connection.msgtype, int(log_time), bytes(data)

    def messages(self, topics: Iterable[str] | None = None) -> Iterator[BagMessage]:
        """Yield decoded rclpy messages in log-time order, optionally only ``topics``.

        A BodyStateArray recorded before BodyState had ``sleeping`` is read with the flags
        false (``codec.StatesCodec.upgrade``); a ContactArray recorded before Contact had
        ``piece_a`` / ``piece_b`` (its recorded definition has none) with those names ''
        (``codec.upgrade_contacts``)."""
        from rclpy.serialization import deserialize_message

        from collres_ros.ros.codec import StatesCodec, upgrade_contacts
        states = StatesCodec()
        for connection, topic, msgtype, log_time, data in self._raw(topics):
            if msgtype == STATES_TYPE:
                data = states.upgrade(data)
            elif msgtype == CONTACTS_TYPE and _before_pieces(connection):
                data = upgrade_contacts(data)
            yield BagMessage(topic, msgtype, log_time,
                             deserialize_message(data, message_class(msgtype)))


def _before_pieces(connection: Any) -> bool:
    """Whether a ContactArray connection was recorded before Contact had piece names: its
    recorded definition (when the bag has one) does not name them."""
    definition = getattr(getattr(connection, 'msgdef', None), 'data', '') or ''
    return bool(definition.strip()) and 'piece_a' not in definition


def read_messages(path: str | Path, topics: Iterable[str] | None = None) -> list[BagMessage]:
    """All (or ``topics``') decoded messages of a bag, in log-time order."""
    with BagReader(path) as reader:
        return list(reader.messages(topics))


def message_fields(msg: Any) -> Any:
    """Return a message as nested plain Python values (dicts, lists, floats) to compare."""
    if hasattr(msg, 'get_fields_and_field_types'):
        return {name: message_fields(getattr(msg, name))
                for name in msg.get_fields_and_field_types()}
    if isinstance(msg, (list, tuple)):
        return [message_fields(item) for item in msg]
    if hasattr(msg, 'tolist'):  # numpy arrays of fixed-size fields
        return msg.tolist()
    return msg
