"""CDR (XCDR1, little endian) encoding and decoding of the package's messages without rclpy.

The bytes are those of ``rclpy.serialization``: a 4-byte encapsulation header
``00 01 00 00``, then the fields, each aligned to its size counted from the
byte after the header; a string is a uint32 length counting its NUL, the
bytes, the NUL.
"""

from __future__ import annotations

import struct
from typing import Any

from collres_ros.core.types import BodyInput

_LE_CDR = b'\x00\x01'  # encapsulation kind: plain CDR, little endian
_STATE = struct.Struct('<13d')  # pose (position 3, orientation 4), twist (linear 3, angular 3)


def decode_body_state_array(data: bytes) -> tuple[int, list[Any]] | None:
    """(stamp ns, BodyInputs) of a serialized BodyStateArray, or None if not plain LE CDR.

    The fast path of replay (rclpy's deserialize_message builds ~10 Python
    objects per body: ~80 us per body). Same result as
    ``messages.inputs_from_array(deserialize_message(data, BodyStateArray))``
    (a test checks it); anything unexpected falls back to that.
    """
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
