"""A bag interrupted (SIGTERM as Ctrl-C: KeyboardInterrupt) while it is written is whole.

The interrupt used to arrive inside the bag library's write of a chunk; the bag was then
closed behind a half-written chunk and sealing it failed (``chunk ... cannot be read``),
losing the bag: in about one of three interrupts here. Writes now take it once the
record is whole, and the bag holds every message written before it.
"""

from __future__ import annotations

import os
import shutil
import signal
import threading
from pathlib import Path

from collres_ros.ros.bag import BagReader, BagWriter

PAYLOAD = bytes(range(256)) * (1 << 14)   # 4 MiB: a chunk of its own
TRIES = 30


def _interrupted_bag(bag: Path) -> tuple[int, int]:
    """(messages written before the interrupt, messages the bag holds)."""
    def interrupt(signum: int, frame: object) -> None:
        raise KeyboardInterrupt

    previous = signal.signal(signal.SIGTERM, interrupt)
    third = threading.Event()

    def kill() -> None:
        if third.wait(60):
            os.kill(os.getpid(), signal.SIGTERM)

    killer = threading.Thread(target=kill)
    killer.start()
    written = 0
    try:
        with BagWriter(bag) as writer:
            for k in range(1000):
                if k == 2:
                    third.set()    # the interrupt arrives in or around the third write
                writer.write_raw('/blob', 'std_msgs/msg/String', k, PAYLOAD)
                written += 1
    except KeyboardInterrupt:
        pass
    finally:
        third.set()
        killer.join()
        signal.signal(signal.SIGTERM, previous)
    with BagReader(bag) as reader:
        return written, sum(1 for _ in reader.raw())


def test_an_interrupt_while_a_chunk_is_written_leaves_a_whole_bag(tmp_path: Path) -> None:
    for k in range(TRIES):
        written, held = _interrupted_bag(tmp_path / f'bag{k}')
        assert written < 1000, 'the interrupt never came'
        assert held >= written, f'try {k}: {written} written, {held} in the bag'
        shutil.rmtree(tmp_path / f'bag{k}')
