"""mcap bags carry their CRCs and are checked against them: a damaged copy is refused.

``rosbags`` writes every mcap CRC as 0, so a flipped bit in a message replayed with
exit 0 and altered data. The tools fill in the chunk, data-section and summary CRCs
(the official ``mcap`` reader validates them), and every mcap bag is checked before it
is read. A failed write leaves no bag behind.
"""

from __future__ import annotations

import shutil
import struct
from pathlib import Path

import numpy as np
import pytest

from collres_ros.replay import main as replay_main
from collres_ros.ros.bag import BagError, BagReader, BagWriter
from collres_ros.sim import main as sim_main

ROOT = Path(__file__).resolve().parents[1]
BALL = ROOT / 'config' / 'scenes' / 'bouncing_ball.yaml'


@pytest.fixture(scope='module')
def recorded(tmp_path_factory: pytest.TempPathFactory) -> Path:
    bag = tmp_path_factory.mktemp('crc') / 'bag'
    assert sim_main(['--offline', '--params', str(BALL), '--record', str(bag),
                     '--duration', '0.3']) == 0
    return bag


def mcap_file(bag: Path) -> Path:
    return next(bag.glob('*.mcap'))


def test_the_official_mcap_reader_validates_every_crc(recorded: Path) -> None:
    from mcap.reader import make_reader
    from mcap.records import Chunk, DataEnd, Footer
    from mcap.stream_reader import StreamReader
    with open(mcap_file(recorded), 'rb') as file:
        records = list(StreamReader(file, emit_chunks=True, validate_crcs=True).records)
    chunks = [r for r in records if isinstance(r, Chunk)]
    data_end = [r for r in records if isinstance(r, DataEnd)]
    footer = [r for r in records if isinstance(r, Footer)]
    print(len(chunks), 'chunks; data CRC', data_end[0].data_section_crc,
          'summary CRC', footer[0].summary_crc)
    assert chunks and all(c.uncompressed_crc for c in chunks)
    assert data_end[0].data_section_crc and footer[0].summary_crc
    with open(mcap_file(recorded), 'rb') as file:
        assert sum(1 for _ in make_reader(file, validate_crcs=True).iter_messages()) > 0


def test_every_flipped_bit_is_refused(recorded: Path, tmp_path: Path) -> None:
    size = mcap_file(recorded).stat().st_size
    rng = np.random.default_rng(15)
    refused = []
    for k, offset in enumerate(sorted(rng.integers(0, size, 60).tolist())):
        copy = tmp_path / f'copy{k}'
        shutil.copytree(recorded, copy)
        path = mcap_file(copy)
        data = bytearray(path.read_bytes())
        data[offset] ^= 1 << int(rng.integers(0, 8))
        path.write_bytes(bytes(data))
        with pytest.raises(BagError) as info:
            with BagReader(copy) as reader:
                list(reader.raw())
        refused.append(str(info.value))
        shutil.rmtree(copy)
    print(len(refused), 'of 60 refused, e.g.', refused[:3])
    assert sum('damaged bag' in text or 'cannot open' in text for text in refused) == 60


def test_a_damaged_length_of_the_data_end_record_is_refused(recorded: Path,
                                                            tmp_path: Path) -> None:
    """The DataEnd record's length lies outside every CRC: a flipped bit there (found by
    the random flips above) made it a longer record holding the same CRC, and the bag was
    read as sound. The records must tile the file up to the summary."""
    copy = tmp_path / 'copy'
    shutil.copytree(recorded, copy)
    path = mcap_file(copy)
    data = bytearray(path.read_bytes())
    footer = len(data) - 8 - 29
    summary_start = struct.unpack_from('<Q', data, footer + 9)[0]
    data_end = summary_start - 13          # opcode, length (8), data_section_crc (4)
    assert data[data_end] == 0x0F and struct.unpack_from('<Q', data, data_end + 1)[0] == 4
    data[data_end + 2] ^= 0x04             # length 4 -> 1028
    path.write_bytes(bytes(data))
    with pytest.raises(BagError, match='damaged bag'):
        with BagReader(copy) as reader:
            list(reader.raw())


def test_replay_of_a_damaged_bag_is_one_error_line(recorded: Path, tmp_path: Path,
                                                   capsys: pytest.CaptureFixture) -> None:
    copy = tmp_path / 'copy'
    shutil.copytree(recorded, copy)
    path = mcap_file(copy)
    data = bytearray(path.read_bytes())
    middle = len(data) // 2     # inside the messages
    data[middle] ^= 0x10
    path.write_bytes(bytes(data))
    assert replay_main([str(copy), str(tmp_path / 'out')]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    print(err)
    assert len(err) == 1 and err[0].startswith(f'error: {copy}: damaged bag, ')
    assert not (tmp_path / 'out').exists()


def test_a_bag_that_failed_to_write_is_removed(tmp_path: Path) -> None:
    from std_msgs.msg import String
    bag = tmp_path / 'failed'
    with pytest.raises(OSError):
        with BagWriter(bag) as writer:
            writer.write('/a', 1, String(data='x'))
            raise OSError(28, 'No space left on device')
    assert not bag.exists()
    kept = tmp_path / 'interrupted'
    with pytest.raises(KeyboardInterrupt):
        with BagWriter(kept) as writer:
            writer.write('/a', 1, String(data='x'))
            raise KeyboardInterrupt
    with BagReader(kept) as reader:   # an interrupt finishes the bag
        assert reader.topic_count('/a') == 1
    assert struct.unpack('<I', mcap_file(kept).read_bytes()[-12:-8])[0] != 0
