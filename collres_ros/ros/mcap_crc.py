"""The CRCs of an mcap file: written after the bag writer closes it, checked before reading.

``rosbags`` writes every CRC of an mcap file as 0 ("not computed"), so a flipped
bit in a message goes unnoticed. mcap defines three (mcap.dev spec): each chunk's
``uncompressed_crc`` (CRC32 of its uncompressed records), the DataEnd record's
``data_section_crc`` (of every byte from the file's start to the DataEnd record)
and the Footer's ``summary_crc`` (from the summary's start through the Footer's
``summary_offset_start``). ``seal`` fills them in place; ``check`` recomputes
every non-zero one and raises ``CrcError`` naming the first that differs (a CRC
of 0 was not written and is not checked, as the spec says). Both read the file
once, record by record (a chunk at a time in memory). sqlite3 bags carry no
checksums. No ROS import.
"""

from __future__ import annotations

import struct
from binascii import crc32
from pathlib import Path
from typing import BinaryIO, Callable

MAGIC = b'\x89MCAP0\r\n'
CHUNK, DATA_END, FOOTER = 0x06, 0x0F, 0x02
FOOTER_SIZE = 1 + 8 + 20   # opcode, length, summary_start, summary_offset_start, summary_crc


class CrcError(ValueError):
    """An mcap CRC that does not match its bytes (the file is damaged)."""


def _decompressor(name: str) -> Callable[[bytes], bytes]:
    if name == '':
        return lambda data: data
    if name == 'zstd':
        try:
            from compression import zstd   # type: ignore[import-not-found]  # Python 3.14
        except ImportError:
            from backports import zstd     # type: ignore[import-not-found,no-redef]
        return zstd.decompress
    if name == 'lz4':
        from lz4.frame import decompress   # type: ignore[import-untyped]
        return decompress
    raise CrcError(f'unknown chunk compression {name[:20]!r}')


def _chunk_crc(content: bytes) -> tuple[int, int]:
    """(offset of uncompressed_crc in the chunk content, CRC32 of its uncompressed records)."""
    size = struct.unpack_from('<Q', content, 16)[0]
    name_length = struct.unpack_from('<I', content, 28)[0]
    name = content[32:32 + name_length].decode('utf-8', errors='replace')
    start = 32 + name_length
    records_length = struct.unpack_from('<Q', content, start)[0]
    records = content[start + 8:start + 8 + records_length]
    raw = _decompressor(name)(bytes(records))
    if len(raw) != size:
        raise CrcError(f'chunk of {len(raw)} bytes where its header says {size}')
    return 24, crc32(raw)


def _walk(file: BinaryIO, write: bool) -> None:
    """Every CRC of the open file: filled in (``write``) or checked (CrcError)."""
    file.seek(0, 2)
    total = file.tell()
    file.seek(0)
    head = file.read(8)
    if head != MAGIC or total < 8 + FOOTER_SIZE + 8:
        raise CrcError('not an mcap file (no magic)')
    running = crc32(head)
    position = 8
    while True:
        if position + 9 > total:
            raise CrcError('no DataEnd record')
        file.seek(position)
        header = file.read(9)
        opcode, length = header[0], struct.unpack_from('<Q', header, 1)[0]
        if position + 9 + length > total:
            raise CrcError(f'record at byte {position} runs past the end of the file')
        if opcode == DATA_END:
            content = bytearray(file.read(length))
            stored = struct.unpack_from('<I', content, 0)[0] if length >= 4 else 0
            if write:
                struct.pack_into('<I', content, 0, running)
                file.seek(position + 9)
                file.write(content)
            elif stored and stored != running:
                raise CrcError('data section CRC differs: the messages were damaged')
            data_end = position + 9 + length
            break
        content = bytearray(file.read(length))
        if opcode == CHUNK:
            try:
                offset, value = _chunk_crc(bytes(content))
            except (struct.error, ValueError, RuntimeError, OSError) as error:
                raise CrcError(f'chunk at byte {position} cannot be read ({error})') from None
            stored = struct.unpack_from('<I', content, offset)[0]
            if write:
                struct.pack_into('<I', content, offset, value)
                file.seek(position + 9)
                file.write(content)
            elif stored and stored != value:
                raise CrcError(f'chunk at byte {position}: CRC differs, its messages were '
                               'damaged')
        running = crc32(bytes(content), crc32(header, running))
        position += 9 + length
    file.seek(total - 8 - FOOTER_SIZE)
    footer = bytearray(file.read(FOOTER_SIZE))
    if footer[0] != FOOTER or file.read(8) != MAGIC:
        raise CrcError('no footer')
    summary_start = struct.unpack_from('<Q', footer, 9)[0]
    if summary_start > total - 8 - FOOTER_SIZE:
        raise CrcError('footer points past the end of the file')
    # the records tile the file: the summary (or, without one, the footer) starts where the
    # DataEnd record ends, so no byte between them lies outside every CRC (a damaged
    # DataEnd length would otherwise be read as a longer record holding the same CRC)
    if data_end != (summary_start or total - 8 - FOOTER_SIZE):
        raise CrcError(f'the data section ends at byte {data_end}, not where the '
                       'summary begins')
    if not summary_start:
        return
    file.seek(summary_start)
    summary = file.read(total - 8 - FOOTER_SIZE - summary_start)
    value = crc32(bytes(footer[:FOOTER_SIZE - 4]), crc32(summary))
    stored = struct.unpack_from('<I', footer, FOOTER_SIZE - 4)[0]
    if write:
        struct.pack_into('<I', footer, FOOTER_SIZE - 4, value)
        file.seek(total - 8 - FOOTER_SIZE)
        file.write(footer)
    elif stored and stored != value:
        raise CrcError('summary CRC differs: the index was damaged')


def seal(path: Path) -> None:
    """Fill in every CRC of the mcap file ``path`` (in place; CrcError if it is malformed)."""
    with open(path, 'r+b') as file:
        _walk(file, write=True)


def check(path: Path) -> None:
    """CrcError naming the first CRC of ``path`` that does not match its bytes."""
    with open(path, 'rb') as file:
        _walk(file, write=False)
