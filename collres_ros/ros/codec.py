"""CDR bytes of the node's messages with numpy: decode and encode without rclpy objects.

The wire format is what ``rclpy.serialization`` (rmw_fastrtps) produces: plain
little-endian CDR (XCDR1), a 4-byte encapsulation header ``00 01 00 00``, then
the fields, each aligned to its size counted from the byte after the header
(float64 on 8, int32/uint32/float32 on 4); a string is a uint32 length that
counts its terminating NUL, the UTF-8 bytes, the NUL; a sequence is a uint32
count, then its elements. Nothing follows the last field, except between
processes: rmw_fastrtps delivers a payload whose size is not a multiple of 4 (a
BodyStateArray ends with a bool) padded with zeros to 4, without saying so in the
encapsulation options; decoding accepts those up to 3 zero bytes.

Decode: ``BodyStateArray`` (``StatesCodec``), ``PoseStamped``,
``TwistStamped`` and ``tf2_msgs/TFMessage`` (``decode_pose``, ``decode_twist``,
``decode_tf``). Encode: ``BodyStateArray``,
``PoseStamped``, ``TwistStamped``, ``WrenchStamped``, ``ContactArray``,
``MarkerArray`` and ``tf2_msgs/TFMessage`` (``encode_*``; the last needs no
tf2_msgs installed). Every decode checks the size of what it is about to read
before it reads it (a message announcing more bodies than the scene has is
refused at once) and refuses negative stamps and ``nanosec >= 1e9``:
``DecodeError`` with a reason key and one line.

``contacts_message`` and ``markers_message`` give the same bytes as a ``Restampable``: a
message that equals the last one but for its stamps (the held contacts of a sleeping pile,
``ResolvedStep.unchanged``) is then restamped in place (one scatter) instead of encoded again.

Padding bytes are written as zeros (rclpy leaves them uninitialised), so
compare decoded values, or bytes outside the padding, never raw bytes with rclpy's.

``BodyState`` ends with ``bool sleeping`` (one byte, 0 or 1, after the 13
doubles; the next body's name then starts on 4). Bodies written before that
field existed (old bags, old publishers: name, 13 doubles, nothing else) are
still decoded, as not sleeping: a message that does not parse with the field
is parsed without it.

Speed: a ``BodyStateArray`` layout (where the names, the padding, the 13
doubles and the ``sleeping`` byte of each body sit) is computed once per (frame, names) and cached;
reading or writing the doubles is then one numpy gather or scatter, and a
received message is checked against the cached layout by one comparison of
its non-float bytes (names, counts, lengths). Names are never assumed: a
message that does not match is parsed field by field.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass, field
from typing import Any, Optional, Sequence

import numpy as np

from collres_ros.core.types import BodyInput

ENCAPSULATION = b'\x00\x01\x00\x00'   # plain CDR, little endian
NS_PER_S = 1_000_000_000
MAX_STRING = 4096       # bytes: a longer name or frame_id is refused (ROS names are < 256)
STATE_DOUBLES = 13      # pose position 3, orientation 4 (x, y, z, w), twist linear 3, angular 3
_LAYOUT_CACHE = 8       # layouts kept per codec
_U32 = struct.Struct('<I')
_STAMP = struct.Struct('<iI')


class DecodeError(ValueError):
    """A message the codec refuses; ``reason`` is a short stable key for the counts."""

    def __init__(self, reason: str, detail: str) -> None:
        super().__init__(detail)
        self.reason = reason


# --- stamps -----------------------------------------------------------------------------------

def stamp_parts(ns: int) -> tuple[int, int]:
    """Integer ns -> (sec, nanosec), nanosec in [0, 1e9); negative times clamp to 0."""
    return divmod(max(int(ns), 0), NS_PER_S)


def check_stamp(sec: int, nanosec: int) -> int:
    """builtin_interfaces/Time fields -> ns; DecodeError for a negative or unnormalised stamp."""
    if sec < 0:
        raise DecodeError('negative_stamp', f'stamp {sec} s {nanosec} ns is negative')
    if nanosec >= NS_PER_S:
        raise DecodeError('invalid_nanosec',
                          f'stamp nanosec {nanosec} is not below 1e9 (not normalised)')
    return sec * NS_PER_S + nanosec


# --- writing ----------------------------------------------------------------------------------

class Writer:
    """Append CDR fields to a buffer (alignment from after the encapsulation header).

    ``padding`` lists the absolute positions of the alignment bytes written
    (zeros), for tests and layouts.
    """

    def __init__(self) -> None:
        self.buf = bytearray(ENCAPSULATION)
        self.padding: list[int] = []

    @property
    def offset(self) -> int:
        """Offset of the next byte from the end of the encapsulation header."""
        return len(self.buf) - 4

    def align(self, size: int) -> None:
        pad = -self.offset % size
        if pad:
            self.padding.extend(range(len(self.buf), len(self.buf) + pad))
            self.buf += bytes(pad)

    def u8(self, value: int) -> None:
        self.buf.append(value & 0xFF)

    def boolean(self, value: bool) -> None:
        self.buf.append(1 if value else 0)

    def i32(self, value: int) -> None:
        self.align(4)
        self.buf += struct.pack('<i', value)

    def u32(self, value: int) -> None:
        self.align(4)
        self.buf += _U32.pack(value)

    def f32s(self, values: Sequence[float]) -> None:
        self.align(4)
        self.buf += struct.pack(f'<{len(values)}f', *values)

    def f64s(self, values: Sequence[float]) -> None:
        self.align(8)
        self.buf += struct.pack(f'<{len(values)}d', *values)

    def f64_array(self, values: np.ndarray) -> None:
        """A block of float64 (any shape, C order), aligned to 8."""
        self.align(8)
        self.buf += np.ascontiguousarray(values, '<f8').tobytes()

    def string(self, text: str) -> None:
        data = text.encode()
        self.u32(len(data) + 1)
        self.buf += data + b'\x00'

    def stamp(self, ns: int) -> None:
        sec, nanosec = stamp_parts(ns)
        self.align(4)
        self.buf += _STAMP.pack(sec, nanosec)

    def header(self, ns: int, frame_id: str) -> None:
        """std_msgs/Header: stamp, frame_id."""
        self.stamp(ns)
        self.string(frame_id)

    def bytes(self) -> bytes:
        return bytes(self.buf)


def string_bytes(text: str) -> bytes:
    """The CDR encoding of one string (length, UTF-8 bytes, NUL), without alignment."""
    data = text.encode()
    return _U32.pack(len(data) + 1) + data + b'\x00'


# --- reading ----------------------------------------------------------------------------------

def padded_to(data: Any, size: int) -> bool:
    """True when ``data`` is a message of ``size`` bytes, as it is or padded with zeros to a
    multiple of 4 (as it arrives from another process)."""
    extra = len(data) - size
    return extra == 0 or (0 < extra < 4 and len(data) % 4 == 0 and not any(data[size:]))


class Reader:
    """Read CDR fields from bytes; every read is bounds-checked (DecodeError 'malformed')."""

    def __init__(self, data: bytes, what: str) -> None:
        self.data = data
        self.what = what
        if len(data) < 4 or data[:2] != ENCAPSULATION[:2]:
            raise DecodeError('malformed', f'{what}: not little-endian CDR '
                                           f'({bytes(data[:4]).hex() or "empty"})')
        self.pos = 4

    def fail(self, why: str) -> DecodeError:
        return DecodeError('malformed', f'{self.what}: {why} at byte {self.pos} of '
                                        f'{len(self.data)}')

    def align(self, size: int) -> None:
        self.pos += -(self.pos - 4) % size

    def need(self, count: int) -> None:
        if self.pos + count > len(self.data):
            raise self.fail(f'truncated (needs {count} more bytes)')

    def u32(self) -> int:
        self.align(4)
        self.need(4)
        (value,) = _U32.unpack_from(self.data, self.pos)
        self.pos += 4
        return int(value)

    def stamp(self) -> int:
        self.align(4)
        self.need(8)
        sec, nanosec = _STAMP.unpack_from(self.data, self.pos)
        self.pos += 8
        return check_stamp(sec, nanosec)

    def string(self) -> str:
        length = self.u32()
        if length > MAX_STRING:
            raise DecodeError('too_large', f'{self.what}: a string of {length} bytes '
                                           f'(more than {MAX_STRING})')
        if length == 0:
            return ''
        self.need(length)
        raw = bytes(self.data[self.pos:self.pos + length])
        self.pos += length
        if raw[-1] != 0:
            raise self.fail('string without its terminating NUL')
        try:
            return raw[:-1].decode()
        except UnicodeDecodeError:
            raise self.fail('string is not UTF-8') from None

    def u8(self) -> int:
        self.need(1)
        value = self.data[self.pos]
        self.pos += 1
        return int(value)

    def f64s(self, count: int) -> np.ndarray:
        self.align(8)
        self.need(8 * count)
        values = np.frombuffer(self.data, '<f8', count, self.pos)
        self.pos += 8 * count
        return values

    def header(self) -> tuple[int, str]:
        """std_msgs/Header -> (stamp ns, frame_id)."""
        return self.stamp(), self.string()


# --- BodyStateArray ---------------------------------------------------------------------------

@dataclass
class DecodedStates:
    """A decoded BodyStateArray: K bodies, pose and twist in ``frame_id``."""

    stamp_ns: int
    frame_id: str
    names: list[str]
    values: np.ndarray   # (K, 13) float64: position, orientation (x, y, z, w), linear, angular
    # (the message's uint8 view, the (K,) positions of its flags): read only when asked for
    flag_bytes: tuple[np.ndarray, np.ndarray] = field(repr=False)
    legacy: bool = False  # written before BodyState had ``sleeping`` (old bags)

    @property
    def flags(self) -> np.ndarray:
        """(K,) uint8 the ``sleeping`` flags as sent (empty: legacy)."""
        raw, where = self.flag_bytes
        return raw[where]

    @property
    def sleeping(self) -> np.ndarray:
        """(K,) bool: the ``sleeping`` flags (False where the field is absent)."""
        return self.flags != 0 if not self.legacy else np.zeros(len(self.names), bool)


@dataclass
class _Layout:
    """Where everything of a BodyStateArray with these names sits."""

    frame_id: str
    names: list[str]
    size: int                # bytes, with the encapsulation header
    template: np.ndarray     # (size rounded up to 4 + 8k,) uint8: stamp 0, floats 0
    rows: np.ndarray         # (K, 13) int64: index of each double in the float64 view
    first: np.ndarray        # (K,) int64: each body's first (``rows[:, 0]``; see _states_of)
    flags: np.ndarray        # (K,) int64: byte of each ``sleeping`` flag (empty: legacy)
    check: np.ndarray        # positions that must equal the template (not options, stamp,
    #                          floats, padding, flags)
    legacy: bool             # bodies without the ``sleeping`` field (written before it existed)
    expected: np.ndarray     # template[check]: what a message of this layout has there
    expected_bytes: bytes    # ``expected`` as bytes

    def matches(self, data: Any, raw: np.ndarray) -> bool:
        """Whether message bytes ``data`` (``raw``: their uint8 view, at least ``size``
        long) have this layout's names, frame and lengths, as ``check`` says: one gather
        and one comparison of bytes."""
        return raw[self.check].tobytes() == self.expected_bytes


def _states_layout(frame_id: str, names: Sequence[str], legacy: bool = False) -> _Layout:
    w = Writer()
    w.header(0, frame_id)
    w.u32(len(names))
    starts = []
    flags = []
    for name in names:
        w.string(name)
        w.align(8)
        starts.append(len(w.buf))
        w.buf += bytes(8 * STATE_DOUBLES)
        if not legacy:
            flags.append(len(w.buf))
            w.boolean(False)
    size = len(w.buf)
    template = np.zeros(4 + 8 * ((size - 4 + 7) // 8), np.uint8)
    template[:size] = np.frombuffer(bytes(w.buf), np.uint8)
    first = (np.array(starts, np.int64) - 4) // 8
    rows = first[:, None] + np.arange(STATE_DOUBLES)
    keep = np.ones(size, bool)
    keep[2:4] = False    # encapsulation options
    keep[4:12] = False
    keep[w.padding] = False
    float_bytes = (4 + 8 * rows.reshape(-1))[:, None] + np.arange(8)
    keep[float_bytes.reshape(-1)] = False
    flag_bytes = np.array(flags, np.int64)
    keep[flag_bytes] = False
    check = np.flatnonzero(keep)
    return _Layout(frame_id, list(names), size, template, rows, first, flag_bytes, check, legacy,
                   template[check], template[check].tobytes())


def _doubles(buffer: Any) -> np.ndarray:
    """The float64 view of a message buffer, element i at byte 4 + 8 i (aligned doubles)."""
    return np.frombuffer(buffer, '<f8', (len(buffer) - 4) // 8, 4)


def _states_of(buffer: Any) -> np.ndarray:
    """Every run of 13 doubles of a message buffer's float64 view (``_doubles``), as an
    (n - 12, 13) view whose rows overlap (strides 8, 8): row i is doubles i .. i + 12, so a
    body's state is row ``_Layout.first``, and K of them are gathered or scattered by K
    indices (not 13 K)."""
    count = (len(buffer) - 4) // 8
    return np.ndarray((max(count - STATE_DOUBLES + 1, 0), STATE_DOUBLES), '<f8', buffer,
                      4, (8, 8))


class StatesCodec:
    """BodyStateArray to and from (stamp, frame, names, (K, 13) values), with layout caches.

    ``max_bodies``: a message announcing more bodies is refused before its
    bodies are read (``too_many_bodies``); None for no limit.
    """

    def __init__(self, max_bodies: Optional[int] = None) -> None:
        self.max_bodies = max_bodies
        self._by_names: dict[tuple[str, tuple[str, ...]], _Layout] = {}
        self._by_size: dict[int, list[_Layout]] = {}
        self._last: Optional[tuple[str, list[str], _Layout]] = None   # the last encode's

    def _remember(self, layout: _Layout) -> _Layout:
        if len(self._by_names) >= _LAYOUT_CACHE or len(self._by_size) >= _LAYOUT_CACHE:
            self._by_names.clear()
            self._by_size.clear()
        if not layout.legacy:       # encode writes the current layout only
            self._by_names[(layout.frame_id, tuple(layout.names))] = layout
        same = self._by_size.setdefault(layout.size, [])
        same.insert(0, layout)
        del same[_LAYOUT_CACHE:]
        return layout

    def layout(self, frame_id: str, names: Sequence[str]) -> _Layout:
        """The layout of a BodyStateArray with these names (cached)."""
        last = self._last   # a stream encodes the same list every step: one comparison
        if last is not None and last[0] == frame_id and isinstance(names, list) \
                and last[1] == names:
            return last[2]
        key = (frame_id, tuple(names))
        found = self._by_names.get(key)
        if found is None:
            found = self._remember(_states_layout(frame_id, names))
        self._last = (frame_id, list(names), found)
        return found

    # encode

    def encode(self, stamp_ns: int, frame_id: str, names: Sequence[str],
               values: np.ndarray, sleeping: Optional[np.ndarray] = None) -> bytes:
        """Serialised BodyStateArray of ``names`` with ``values`` (K, 13) at ``stamp_ns``;
        ``sleeping`` (K,) bool flags (default: none sleeps)."""
        layout = self.layout(frame_id, names)
        buf = layout.template.copy()
        _STAMP.pack_into(buf, 4, *stamp_parts(stamp_ns))
        if len(names):
            _states_of(buf)[layout.first] = np.asarray(values, float).reshape(-1, STATE_DOUBLES)
            if sleeping is not None:
                buf[layout.flags] = np.asarray(sleeping, bool)
        return buf[:layout.size].tobytes()

    # decode

    def decode(self, data: bytes) -> DecodedStates:
        """DecodedStates of serialised BodyStateArray bytes; DecodeError when refused."""
        reader = Reader(data, 'BodyStateArray')
        stamp = reader.stamp()
        raw = np.frombuffer(data, np.uint8)
        for size in range(len(data), len(data) - 4, -1) if len(data) % 4 == 0 else (len(data),):
            for layout in self._by_size.get(size, ()):
                if layout.matches(data, raw) and padded_to(data, size):
                    return self._decoded(stamp, layout, data, raw)
        frame_id = reader.string()
        count = reader.u32()
        if self.max_bodies is not None and count > self.max_bodies:
            raise DecodeError('too_many_bodies', f'BodyStateArray of {count} bodies, more '
                                                 f'than the {self.max_bodies} of the scene')
        # every body takes at least 4 (name length) + 1 (NUL) + 104 bytes, padding aside
        if count * (5 + 8 * STATE_DOUBLES) > len(data) - reader.pos:
            raise reader.fail(f'{count} bodies announced, not that many bytes')
        start = reader.pos
        try:
            layout = _parse_bodies(reader, frame_id, count, raw, legacy=False)
        except DecodeError as refusal:
            reader.pos = start
            try:   # written before BodyState had ``sleeping``?
                layout = _parse_bodies(reader, frame_id, count, raw, legacy=True)
            except DecodeError:
                raise refusal from None
        self._remember(layout)
        return self._decoded(stamp, layout, data, raw)

    def upgrade(self, data: bytes) -> bytes:
        """BodyStateArray bytes in the current layout: a message written before BodyState
        had ``sleeping`` is re-encoded with the flags false; any other (or refused) message
        is returned as it is."""
        try:
            decoded = self.decode(data)
        except DecodeError:
            return data
        if not decoded.legacy:
            return data
        return self.encode(decoded.stamp_ns, decoded.frame_id, decoded.names, decoded.values)

    @staticmethod
    def _decoded(stamp: int, layout: _Layout, data: bytes, raw: np.ndarray) -> DecodedStates:
        return DecodedStates(stamp, layout.frame_id, layout.names, _states_of(data)[layout.first],
                             (raw, layout.flags), layout.legacy)


def _parse_bodies(reader: Reader, frame_id: str, count: int, raw: np.ndarray,
                  legacy: bool) -> _Layout:
    """The layout of the ``count`` bodies that follow, read field by field (with or without
    the ``sleeping`` byte); DecodeError when the bytes do not fit it."""
    names = []
    for _ in range(count):
        names.append(reader.string())
        reader.f64s(STATE_DOUBLES)
        if not legacy:
            reader.u8()
    if not padded_to(reader.data, reader.pos):
        raise reader.fail(f'{len(reader.data) - reader.pos} bytes after the last body')
    layout = _states_layout(frame_id, names, legacy)
    if layout.size != reader.pos or not np.array_equal(raw[layout.check], layout.expected):
        raise reader.fail('layout does not match the names')
    return layout


def decode_body_state_array(data: bytes) -> tuple[int, list[BodyInput]] | None:
    """(stamp ns, BodyInputs) of serialised BodyStateArray bytes, None when refused.

    The same values as ``messages.inputs_from_array(deserialize_message(data,
    BodyStateArray))`` (a test checks it).
    """
    try:
        decoded = StatesCodec().decode(data)
    except DecodeError:
        return None
    rows = decoded.values.tolist()
    frame = decoded.frame_id
    return decoded.stamp_ns, [
        BodyInput(name, tuple(v[0:3]), tuple(v[3:7]), tuple(v[7:10]),  # type: ignore[arg-type]
                  tuple(v[10:13]), frame, frame) for name, v in zip(decoded.names, rows)]


# --- PoseStamped, TwistStamped ----------------------------------------------------------------

@dataclass(frozen=True)
class Stamped:
    """A decoded PoseStamped (7 values: position, orientation x, y, z, w) or TwistStamped
    (6 values: linear, angular)."""

    stamp_ns: int
    frame_id: str
    values: tuple[float, ...]


_POSE = struct.Struct('<7d')
_TWIST = struct.Struct('<6d')


# (values' size, message size, its encapsulation's first two bytes and its frame_id as
# serialised, length included) -> (frame_id, where its values start), of the stamped
# messages decoded before: a stream's next message of the same frame is read with one
# lookup (its stamp checked, its values unpacked), not field by field (9 us -> 2.5 us a
# message in the node's per-body path, 200 a step at 100 bodies)
_STAMPED_FRAMES: dict[tuple[int, int, bytes, bytes], tuple[str, int]] = {}


def _decode_stamped(data: bytes, what: str, layout: struct.Struct) -> Stamped:
    if len(data) >= 16:
        (length,) = _U32.unpack_from(data, 12)
        key = (layout.size, len(data), data[:2], data[12:16 + length])
        known = _STAMPED_FRAMES.get(key)
        if known is not None:   # the same bytes around the stamp and the values: as below
            return Stamped(check_stamp(*_STAMP.unpack_from(data, 4)), known[0],
                           layout.unpack_from(data, known[1]))
    reader = Reader(data, what)
    if len(data) > 4 + 8 + 4 + MAX_STRING + 8 + layout.size:
        raise DecodeError('too_large', f'{what} of {len(data)} bytes')
    stamp, frame_id = reader.header()
    reader.align(8)
    reader.need(layout.size)
    values = layout.unpack_from(data, reader.pos)
    if reader.pos + layout.size != len(data):
        raise reader.fail('trailing bytes')
    if len(_STAMPED_FRAMES) >= _LAYOUT_CACHE:
        _STAMPED_FRAMES.clear()
    (length,) = _U32.unpack_from(data, 12)
    _STAMPED_FRAMES[(layout.size, len(data), data[:2], data[12:16 + length])] = \
        (frame_id, reader.pos)
    return Stamped(stamp, frame_id, values)


def decode_pose(data: bytes) -> Stamped:
    """Stamped of serialised geometry_msgs/PoseStamped bytes; DecodeError when refused."""
    return _decode_stamped(data, 'PoseStamped', _POSE)


def decode_twist(data: bytes) -> Stamped:
    """Stamped of serialised geometry_msgs/TwistStamped bytes; DecodeError when refused."""
    return _decode_stamped(data, 'TwistStamped', _TWIST)


def _stamped_prefix(stamp_ns: int, frame_id: str) -> bytes:
    w = Writer()
    w.header(stamp_ns, frame_id)
    w.align(8)
    return w.bytes()


def encode_stamped(stamp_ns: int, frame_id: str, values: np.ndarray) -> list[bytes]:
    """Serialised PoseStamped (values (K, 7)), TwistStamped or WrenchStamped ((K, 6): linear,
    angular or force, torque) messages, one per row, all with the header (stamp_ns,
    frame_id): a header, then doubles aligned to 8."""
    prefix = _stamped_prefix(stamp_ns, frame_id)
    rows = np.ascontiguousarray(values, '<f8')
    flat = rows.tobytes()
    width = 8 * rows.shape[1] if rows.ndim == 2 else 0
    return [prefix + flat[k * width:(k + 1) * width] for k in range(rows.shape[0])]


def encode_pose(stamp_ns: int, frame_id: str, values: Sequence[float]) -> bytes:
    """Serialised geometry_msgs/PoseStamped: position, orientation (x, y, z, w)."""
    return _stamped_prefix(stamp_ns, frame_id) + _POSE.pack(*values)


def encode_twist(stamp_ns: int, frame_id: str, values: Sequence[float]) -> bytes:
    """Serialised geometry_msgs/TwistStamped: linear, angular."""
    return _stamped_prefix(stamp_ns, frame_id) + _TWIST.pack(*values)


def encode_wrench(stamp_ns: int, frame_id: str, values: Sequence[float]) -> bytes:
    """Serialised geometry_msgs/WrenchStamped: force (N), torque (N m)."""
    return _stamped_prefix(stamp_ns, frame_id) + _TWIST.pack(*values)


def encode_tf(stamp_ns: int, frame_id: str, children: NamePool, poses: np.ndarray) -> bytes:
    """Serialised tf2_msgs/TFMessage: ``frame_id`` -> each child of ``children`` at its pose
    (rows of ``poses`` (N, 7): translation m, rotation x, y, z, w), all at ``stamp_ns``.

    Each TransformStamped: header (stamp, frame_id), child_frame_id, then on 8
    bytes the 7 doubles; the strings are the pool's, padded as the alignment needs.
    """
    poses = np.ascontiguousarray(poses, '<f8').reshape(-1, 7)
    header = _STAMP.pack(*stamp_parts(stamp_ns)) + string_bytes(frame_id)
    buf = bytearray(ENCAPSULATION)
    buf += _U32.pack(len(poses))
    for k in range(len(poses)):
        _pad(buf, 4)
        buf += header
        _pad(buf, 4)
        buf += children.pool[children.start[k]:children.start[k] + children.words[k]
                             ].tobytes()[:int(children.length[k])]
        _pad(buf, 8)
        buf += poses[k].tobytes()
    return bytes(buf)


@dataclass(frozen=True)
class Transform:
    """One decoded geometry_msgs/TransformStamped of a TFMessage: ``child`` in ``parent``
    at ``stamp_ns``, ``values`` translation (m) then rotation x, y, z, w."""

    stamp_ns: int
    parent: str
    child: str
    values: tuple[float, ...]


_TRANSFORM_BYTES = 4 + 8 + 4 + 4 + 56   # the least a TransformStamped takes (empty names)


def decode_tf(data: bytes) -> list[Transform]:
    """The transforms of serialised tf2_msgs/TFMessage bytes (/tf, /tf_static); DecodeError
    when refused (malformed, truncated, trailing bytes)."""
    reader = Reader(data, 'TFMessage')
    count = reader.u32()
    if count * _TRANSFORM_BYTES > len(data):
        raise reader.fail(f'{count} transforms cannot fit')
    out = []
    for _ in range(count):
        stamp, parent = reader.header()
        child = reader.string()
        values = reader.f64s(7)
        out.append(Transform(stamp, parent, child, tuple(float(v) for v in values)))
    if not padded_to(data, reader.pos):
        raise reader.fail('trailing bytes')
    return out


# --- restamping --------------------------------------------------------------------------------

class Restampable:
    """An encoded message whose stamps (``builtin_interfaces/Time``) can be rewritten in
    place, for a message that is the same as the last one but for its stamps (the held
    contacts of a sleeping pile): one scatter instead of encoding it again.

    ``buffer``: the message bytes (uint8, writable, at least ``size`` long and a whole
    number of 4-byte words); ``stamps``: where each stamp starts, in 4-byte words from after
    the encapsulation header (a stamp is 4-aligned: int32 sec, uint32 nanosec).
    """

    def __init__(self, buffer: np.ndarray, size: int, stamps: np.ndarray) -> None:
        self.buffer, self.size = buffer, size
        self.stamps = np.asarray(stamps, np.int64)
        self._nanosec = self.stamps + 1   # the words of their nanoseconds
        self._words = buffer[4:4 + 4 * ((len(buffer) - 4) // 4)].view('<i4')

    def data(self) -> bytes:
        return self.buffer[:self.size].tobytes()

    def restamped(self, stamps_ns: int | np.ndarray) -> bytes:
        """The message with its stamps set to ``stamps_ns`` (ns: one for all, or one per
        stamp in the order of ``stamps``; negative times clamp to 0)."""
        self.stamp(stamps_ns)
        return self.data()

    def stamp(self, stamps_ns: int | np.ndarray) -> None:
        """Set the stamps in place (``restamped``)."""
        # (nanoseconds < 1e9 fit the int32 words as they are, as uint32 would)
        sec, nanosec = np.divmod(np.maximum(np.asarray(stamps_ns, np.int64), 0), NS_PER_S)
        self._words[self.stamps] = sec
        self._words[self._nanosec] = nanosec


# --- ContactArray -----------------------------------------------------------------------------

class NamePool:
    """The CDR strings of a fixed list of names, padded to 4 bytes, as one uint32 array.

    Sequences of records that start with such strings are then filled with
    one gather (``ContactArray``: body_a, body_b of every contact).
    """

    def __init__(self, names: Sequence[str]) -> None:
        pieces = [string_bytes(n) for n in names]
        self.length = np.array([len(p) for p in pieces], np.int64)           # bytes, unpadded
        self.words = (self.length + 3) // 4                                  # uint32 words
        self.start = np.concatenate([[0], np.cumsum(self.words)[:-1]]).astype(np.int64) \
            if pieces else np.zeros(0, np.int64)
        padded = b''.join(p + bytes(-len(p) % 4) for p in pieces)
        self.pool = np.frombuffer(padded, '<u4') if padded else np.zeros(0, '<u4')
        # the same strings as rows of one width (zero-filled), for records of one shape
        width = int(4 * self.words.max()) if pieces else 0
        self.rows = np.zeros((len(pieces), width), np.uint8)
        for k, piece in enumerate(pieces):
            self.rows[k, :len(piece)] = np.frombuffer(piece, np.uint8)


def _gather_words(out_words: np.ndarray, dest: np.ndarray, pool: NamePool,
                  which: np.ndarray) -> None:
    """Copy the padded strings ``which`` (body indices) to word offsets ``dest`` of the output."""
    if not len(which):
        return
    words = pool.words[which]
    total = int(words.sum())
    base = np.repeat(np.cumsum(words) - words, words)
    within = np.arange(total) - base
    out_words[np.repeat(dest, words) + within] = pool.pool[np.repeat(pool.start[which], words)
                                                           + within]


NO_PIECES = NamePool([''])   # every contact between bodies of one shape: piece names ''


def encode_contacts(stamp_ns: int, frame_id: str, pool: NamePool, body_a: np.ndarray,
                    body_b: np.ndarray, point: np.ndarray, normal: np.ndarray,
                    depth: np.ndarray, toi_ns: np.ndarray, normal_impulse: np.ndarray,
                    friction_impulse: np.ndarray, state: np.ndarray,
                    pieces: tuple[NamePool, np.ndarray, np.ndarray] | None = None) -> bytes:
    """Serialised collres_ros/ContactArray of M contacts (names from ``pool`` by body index;
    ``pieces``: a pool of piece names and each contact's index in it for piece_a and
    piece_b, None: every piece name '').

    Record k: body_a, body_b, piece_a, piece_b (strings, each 4-aligned), then on 8
    bytes: position (3), normal (3), depth, time_of_impact (int32 sec, uint32 nanosec),
    normal_impulse, friction_impulse (3), then state (uint8). Records start 4-aligned;
    after the first one, always at 4 mod 8 (97 bytes of block + 3 of padding).
    """
    return contacts_message(stamp_ns, frame_id, pool, body_a, body_b, point, normal, depth,
                            toi_ns, normal_impulse, friction_impulse, state, pieces).data()


def contacts_message(stamp_ns: int, frame_id: str, pool: NamePool, body_a: np.ndarray,
                     body_b: np.ndarray, point: np.ndarray, normal: np.ndarray,
                     depth: np.ndarray, toi_ns: np.ndarray, normal_impulse: np.ndarray,
                     friction_impulse: np.ndarray, state: np.ndarray,
                     pieces: tuple[NamePool, np.ndarray, np.ndarray] | None = None
                     ) -> 'Restampable':
    """``encode_contacts`` as a ``Restampable``: its stamps are the header's, then each
    contact's time_of_impact."""
    return ContactsEncoder().message(stamp_ns, frame_id, pool, body_a, body_b, point, normal,
                                     depth, toi_ns, normal_impulse, friction_impulse, state,
                                     pieces)


@dataclass
class _ContactsShape:
    """Where everything of a ContactArray of these pairs sits: its names written, its
    numbers and stamps still to write (``_contacts_fields``)."""

    frame_id: str
    pool: NamePool
    pieces: Optional[NamePool]
    a: np.ndarray             # (M,) int64 body_a, body_b, piece_a, piece_b indices
    b: np.ndarray
    pa: np.ndarray
    pb: np.ndarray
    message: 'Restampable'    # the buffer: header, count, names, padding
    block: np.ndarray         # (M,) int64: byte of each record's numbers, after the header
    # records 1.. of one shape (names that pad to the same lengths): (first byte, record
    # length, its numbers' offset in it) of record 0 and of the rest; None: not uniform
    uniform: Optional[tuple[tuple[int, int, int], tuple[int, int, int]]]

    def fits(self, frame_id: str, pool: NamePool, a: np.ndarray, b: np.ndarray,
             pieces: tuple[NamePool, np.ndarray, np.ndarray] | None) -> bool:
        """Whether a message of these pairs has this shape (the same strings in order)."""
        if frame_id != self.frame_id or pool is not self.pool or len(a) != len(self.a) \
                or (pieces is None) != (self.pieces is None):
            return False
        if pieces is not None and (pieces[0] is not self.pieces
                                   or not np.array_equal(pieces[1], self.pa)
                                   or not np.array_equal(pieces[2], self.pb)):
            return False
        return bool((a == self.a).all() and (b == self.b).all())


def _contacts_shape(frame_id: str, pool: NamePool, a: np.ndarray, b: np.ndarray,
                    pieces: tuple[NamePool, np.ndarray, np.ndarray] | None) -> _ContactsShape:
    """The shape of a ContactArray of the pairs ``a``, ``b`` (int64 body indices into
    ``pool``) and ``pieces``: its buffer with the header (stamp 0), the count, every name
    and zero padding written."""
    w = Writer()
    w.header(0, frame_id)
    count = int(len(a))
    w.u32(count)
    names, pa, pb = pieces if pieces is not None else (
        NO_PIECES, np.zeros(count, np.int64), np.zeros(count, np.int64))
    pa, pb = np.array(pa, np.int64), np.array(pb, np.int64)
    piece_pool = None if pieces is None else names
    if count == 0:
        empty = Restampable(np.frombuffer(w.bytes(), np.uint8).copy(), len(w.buf),
                            np.array([0], np.int64))
        return _ContactsShape(frame_id, pool, piece_pool, a.copy(), b.copy(), pa, pb, empty,
                              np.zeros(0, np.int64), None)
    s0 = w.offset                                          # 4-aligned
    la = 4 * pool.words[a]                                 # body_a, padded to 4
    lb4 = 4 * pool.words[b]                                # body_b, padded to 4
    lpa4 = 4 * names.words[pa]                             # piece_a, padded to 4
    strings = la + lb4 + lpa4 + names.length[pb]           # to the end of piece_b
    phase = np.full(count, 4, np.int64)
    phase[0] = s0 % 8
    gap = -(phase + strings) % 8
    record = strings + gap + 100
    start = s0 + np.concatenate([[0], np.cumsum(record[:-1])])   # from after the header
    block = start + strings + gap                          # 8-aligned
    size = 4 + int(block[-1]) + 97
    buf = np.zeros(4 + 8 * ((size - 4 + 7) // 8) + 8, np.uint8)
    head = np.frombuffer(bytes(w.buf), np.uint8)
    buf[:len(head)] = head
    message = Restampable(buf, size, np.concatenate([[0], (block + 56) // 4]))
    # records after the first one all start at 4 mod 8: when their names pad to the same
    # lengths (as in most scenes) they have one shape, written through one strided view
    rest = slice(1, count)
    uniform = count > 2 and all((x[rest] == x[1]).all() for x in (record, la, lb4, lpa4))
    if not uniform:
        words = buf[4:4 + 4 * ((len(buf) - 4) // 4)].view('<u4')
        for string_pool, which, at in ((pool, a, start), (pool, b, start + la),
                                       (names, pa, start + la + lb4),
                                       (names, pb, start + la + lb4 + lpa4)):
            _gather_words(words, at // 4, string_pool, which)
        return _ContactsShape(frame_id, pool, piece_pool, a.copy(), b.copy(), pa, pb, message,
                              block, None)
    # the first record (its own phase) and the rest, each of one shape
    geometry = []
    for k in (slice(0, 1), rest):
        i = k.start
        _contacts_names(buf, ((pool, a[k], int(la[i])), (pool, b[k], int(lb4[i])),
                              (names, pa[k], int(lpa4[i])),
                              # the longest: shorter ones write zeros into the gap
                              (names, pb[k], int(4 * names.words[pb[k]].max()))),
                        int(start[i]), int(record[i]))
        geometry.append((int(start[i]), int(record[i]), int(block[i] - start[i])))
    return _ContactsShape(frame_id, pool, piece_pool, a.copy(), b.copy(), pa, pb, message,
                          block, (geometry[0], geometry[1]))


class ContactsEncoder:
    """``contacts_message`` that remembers the shape of its last message: a message of the
    same pairs in the same order (body and piece indices: a settled pile's contacts, step
    after step) is written into the last one's buffer, its numbers and stamps only (its
    names, offsets and padding are as they were). The same bytes as a message built anew.

    The last message's buffer is written in place: take its bytes (``Restampable.data``)
    before the next call.
    """

    def __init__(self) -> None:
        self._last: Optional[_ContactsShape] = None

    def message(self, stamp_ns: int, frame_id: str, pool: NamePool, body_a: np.ndarray,
                body_b: np.ndarray, point: np.ndarray, normal: np.ndarray,
                depth: np.ndarray, toi_ns: np.ndarray, normal_impulse: np.ndarray,
                friction_impulse: np.ndarray, state: np.ndarray,
                pieces: tuple[NamePool, np.ndarray, np.ndarray] | None = None
                ) -> 'Restampable':
        """The ContactArray of ``encode_contacts``' arguments, as a ``Restampable``."""
        a = np.asarray(body_a, np.int64)
        b = np.asarray(body_b, np.int64)
        shape = self._last
        if shape is None or not shape.fits(frame_id, pool, a, b, pieces):
            shape = self._last = _contacts_shape(frame_id, pool, a, b, pieces)
        buf = shape.message.buffer
        _STAMP.pack_into(buf, 4, *stamp_parts(stamp_ns))
        count = len(a)
        if count:
            _contacts_fields(buf, shape, dict(
                point=np.asarray(point, float).reshape(count, 3),
                normal=np.asarray(normal, float).reshape(count, 3),
                depth=np.asarray(depth, float).reshape(count, 1),
                toi=np.maximum(np.asarray(toi_ns, np.int64), 0),
                impulse=np.asarray(normal_impulse, float).reshape(count, 1),
                friction=np.asarray(friction_impulse, float).reshape(count, 3),
                state=np.asarray(state, np.uint8)))
        return shape.message


def upgrade_contacts(data: bytes) -> bytes:
    """A ContactArray recorded before Contact had ``piece_a`` / ``piece_b`` (bags of earlier
    versions), in today's layout with those names '' (DecodeError when it is malformed)."""
    r = Reader(data, 'ContactArray (before piece_a)')
    stamp, frame = r.header()
    count = r.u32()
    names: dict[str, int] = {}
    pairs, values, toi, state = [], [], [], []
    for _ in range(count):
        pairs.append([names.setdefault(r.string(), len(names)) for _ in range(2)])
        head = r.f64s(7)                      # position, normal, depth
        toi.append(r.stamp())
        values.append(np.concatenate([head, r.f64s(4)]))   # normal impulse, friction
        state.append(r.u8())
    index = np.array(pairs, np.int64).reshape(count, 2)
    v = np.array(values, float).reshape(count, 11)
    return encode_contacts(stamp, frame, NamePool(list(names)), index[:, 0], index[:, 1],
                           v[:, 0:3], v[:, 3:6], v[:, 6], np.array(toi, np.int64), v[:, 7],
                           v[:, 8:11], np.array(state, np.uint8))


def _contacts_names(buf: np.ndarray, strings: Sequence[tuple[NamePool, np.ndarray, int]],
                    start: int, length: int) -> None:
    """The strings of contact records of one shape (``length`` bytes each) from ``start``;
    ``strings``: the record's four (pool, indices, padded length) in order."""
    count = len(strings[0][1])
    records = buf[4 + start:4 + start + count * length].reshape(count, length)
    at = 0
    for pool, which, padded in strings:
        # one name in the pool (every piece name ''): the same bytes in every record
        records[:, at:at + padded] = pool.rows[0, :padded] if len(pool.rows) == 1 \
            else pool.rows[which, :padded]
        at += padded


def _contacts_fields(buf: np.ndarray, shape: _ContactsShape, col: dict[str, np.ndarray]
                     ) -> None:
    """The numbers of every contact record of ``shape`` (its names are written): through
    one strided view per run of records of one shape, else scattered."""
    if shape.uniform is None:
        f8 = _doubles(buf)
        j = shape.block // 8
        f8[j[:, None] + np.arange(7)] = np.concatenate([col['point'], col['normal'],
                                                        col['depth']], axis=1)
        f8[j[:, None] + np.arange(8, 12)] = np.concatenate([col['impulse'], col['friction']],
                                                           axis=1)
        i4 = buf[4:4 + 4 * ((len(buf) - 4) // 4)].view('<i4')
        i4[(shape.block + 56) // 4] = col['toi'] // NS_PER_S
        i4[(shape.block + 60) // 4] = col['toi'] % NS_PER_S
        buf[4 + shape.block + 96] = col['state']
        return
    head = np.concatenate([col['point'], col['normal'], col['depth']], axis=1)
    tail = np.concatenate([col['impulse'], col['friction']], axis=1)
    sec, nanosec = col['toi'] // NS_PER_S, col['toi'] % NS_PER_S
    count = len(head)
    for k, (start, length, block) in zip((slice(0, 1), slice(1, count)), shape.uniform):
        n = k.stop - k.start
        records = buf[4 + start:4 + start + n * length].reshape(n, length)
        fields = records[:, block:block + 96]
        fields[:, 0:56].view('<f8')[:] = head[k]
        stamps = fields[:, 56:64].view('<i4')
        stamps[:, 0] = sec[k]
        stamps[:, 1] = nanosec[k]
        fields[:, 64:96].view('<f8')[:] = tail[k]
        records[:, block + 96] = col['state'][k]


# --- MarkerArray ------------------------------------------------------------------------------

@dataclass
class MarkerSpec:
    """One visualization_msgs/Marker for ``encode_markers`` (the fields the node sets).

    ``points`` (P, 3) m and ``colors`` (P, 4) RGBA in [0, 1] for list markers;
    ``scale`` (3,), ``color`` (4,), ``pose`` (7,) position + orientation x, y, z, w.
    """

    action: int
    type: int = 0
    ns: str = ''
    id: int = 0
    pose: tuple[float, ...] = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0)
    scale: tuple[float, float, float] = (0.0, 0.0, 0.0)
    color: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 0.0)
    lifetime_ns: int = 0
    points: Optional[np.ndarray] = None
    colors: Optional[np.ndarray] = None


def _pad(buf: bytearray, size: int) -> None:
    """Zero bytes up to the next multiple of ``size`` (counted from after the header)."""
    buf += _ZEROS[:-(len(buf) - 4) % size]


_ZEROS = bytes(8)
_MARKER_IDS = struct.Struct('<iii')         # id, type, action
_MARKER_BODY = struct.Struct('<10d4fiIB')   # pose 7, scale 3, color 4, lifetime, frame_locked


def _marker_tail() -> bytes:
    """The empty fields after ``colors``: texture_resource, texture (CompressedImage:
    header, format, data), uv_coordinates, text, mesh_resource, mesh_file (filename,
    data), mesh_use_embedded_materials. Aligned to 4 at most, and it starts 4-aligned:
    the same bytes after every marker."""
    w = Writer()
    w.string('')
    w.header(0, '')
    w.string('')
    w.u32(0)
    w.u32(0)
    w.string('')
    w.string('')
    w.string('')
    w.u32(0)
    w.u8(0)
    return w.bytes()[4:]


_MARKER_TAIL = _marker_tail()


def encode_markers(stamp_ns: int, frame_id: str, markers: Sequence[MarkerSpec]) -> bytes:
    """Serialised visualization_msgs/MarkerArray (Jazzy's Marker: texture, uv, mesh_file empty)."""
    return markers_message(stamp_ns, frame_id, markers).data()


def markers_message(stamp_ns: int, frame_id: str, markers: Sequence[MarkerSpec]
                    ) -> Restampable:
    """``encode_markers`` as a ``Restampable``: its stamps are each marker's header's."""
    return _markers_shape(stamp_ns, frame_id, markers).message


@dataclass
class _MarkersShape:
    """A MarkerArray's bytes and where each marker's ``points`` and ``colors`` sit in them."""

    key: tuple[Any, ...]        # frame and every field but the points' and colours' values
    message: Restampable
    points_at: list[int]        # byte of each marker's first point (float64), -1: none
    colors_at: list[int]        # byte of each marker's first colour (float32), -1: none


def _markers_key(frame_id: str, markers: Sequence[MarkerSpec]) -> tuple[Any, ...]:
    """What fixes a MarkerArray's bytes but the values of its points and colours."""
    return (frame_id, *((m.action, m.type, m.ns, m.id, int(m.lifetime_ns),
                         _MARKER_BODY.pack(*m.pose, *m.scale, *m.color, 0, 0, 0),
                         0 if m.points is None else len(m.points),
                         0 if m.colors is None else len(m.colors)) for m in markers))


def _markers_shape(stamp_ns: int, frame_id: str, markers: Sequence[MarkerSpec]
                   ) -> _MarkersShape:
    buf = bytearray(ENCAPSULATION)
    buf += _U32.pack(len(markers))
    header = _STAMP.pack(*stamp_parts(stamp_ns)) + string_bytes(frame_id)
    stamps, points_at, colors_at = [], [], []
    for m in markers:
        _pad(buf, 4)
        stamps.append((len(buf) - 4) // 4)
        buf += header
        _pad(buf, 4)
        buf += string_bytes(m.ns)
        _pad(buf, 4)
        buf += _MARKER_IDS.pack(m.id, m.type, m.action)
        _pad(buf, 8)
        sec, nanosec = divmod(int(m.lifetime_ns), NS_PER_S)
        buf += _MARKER_BODY.pack(*m.pose, *m.scale, *m.color, sec, nanosec, 0)
        points = () if m.points is None else m.points
        _pad(buf, 4)
        buf += _U32.pack(len(points))
        points_at.append(-1)
        if len(points):
            _pad(buf, 8)
            points_at[-1] = len(buf)
            buf += np.ascontiguousarray(points, '<f8').tobytes()
        colors = () if m.colors is None else m.colors
        _pad(buf, 4)
        buf += _U32.pack(len(colors))
        colors_at.append(-1)
        if len(colors):
            colors_at[-1] = len(buf)
            buf += np.ascontiguousarray(colors, '<f4').tobytes()
        buf += _MARKER_TAIL
    size = len(buf)
    buf += bytes(-(size - 4) % 4)
    message = Restampable(np.frombuffer(buf, np.uint8), size, np.array(stamps, np.int64))
    return _MarkersShape(_markers_key(frame_id, markers), message, points_at, colors_at)


class MarkersEncoder:
    """``markers_message`` that remembers its last message: markers that differ from the
    last ones only in the values of their points and colours (the same markers, lifetimes
    and point counts: a settled pile's contacts, step after step) are written into the last
    message's buffer, points, colours and stamps only. The same bytes as a message built
    anew. The last message's buffer is written in place: take its bytes first."""

    def __init__(self) -> None:
        self._last: Optional[_MarkersShape] = None

    def message(self, stamp_ns: int, frame_id: str, markers: Sequence[MarkerSpec]
                ) -> Restampable:
        shape = self._last
        if shape is None or shape.key != _markers_key(frame_id, markers):
            shape = self._last = _markers_shape(stamp_ns, frame_id, markers)
            return shape.message
        buf = shape.message.buffer
        for m, points, colors in zip(markers, shape.points_at, shape.colors_at):
            if points >= 0:
                count = 3 * len(m.points)
                buf[points:points + 8 * count].view('<f8')[:] = \
                    np.asarray(m.points, float).reshape(-1)
            if colors >= 0:
                count = 4 * len(m.colors)
                buf[colors:colors + 4 * count].view('<f4')[:] = \
                    np.asarray(m.colors, '<f4').reshape(-1)
        shape.message.stamp(stamp_ns)
        return shape.message
