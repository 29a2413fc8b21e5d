"""``rtsar bench``'s recording row: how fast ``run --record`` writes a stream's raw shots to
this machine's disk, and whether it keeps up with the stream (rtsar.sinks.raw_record).

Two measurements with the recorder itself, on blocks of shots made once (noise, incompressible):

* **paced**: the stream at its PRF (psaltis-max: 10 kHz × 1800 samples × 8 B = 144 MB/s) for
  ``seconds``, handed over as the pipeline hands it (never waiting); the rate written and what
  the disk could not take (``record_dropped``);
* **as fast as it takes them**: blocks handed whenever the recorder's queue has room, for
  ``seconds``; the sustained rate, to the operating system's page cache, and with the file
  synced to the disk at the end (``fsync``), the rate a longer recording settles at once the
  cache is full.

Not a test: figures vary with the disk and with the other jobs on it.
"""

from __future__ import annotations

import os
import shutil
import tempfile
import time
from pathlib import Path

import numpy as np

from ..params import Config
from ..sinks.raw_record import ShotRecorder
from ..stream.ingest import PulseBlock

BLOCK = 64  # pulses per block handed over (the pipeline's micro-batches are this order)


def _blocks(config: Config, count: int = 16) -> list[np.ndarray]:
    s = config.waveform.samples_per_shot
    rng = np.random.default_rng(0)
    x = rng.standard_normal((count, BLOCK, 2 * s)).astype(np.float32)
    return list(x.view(np.complex64))


def _block(first: int, samples: np.ndarray, prf_hz: float) -> PulseBlock:
    n = len(samples)
    seq = np.arange(first, first + n)
    return PulseBlock(
        first, samples, np.zeros(n), np.zeros(n, bool), {}, seq, seq / prf_hz, np.zeros(n, bool)
    )


def _paced(config: Config, path: Path, seconds: float, blocks) -> dict:
    prf = config.geometry.prf_hz
    rec = ShotRecorder(path, config)
    t0 = time.perf_counter()
    first = 0
    while first < seconds * prf:
        due = t0 + (first + BLOCK) / prf  # the block's last shot arrives then
        wait = due - time.perf_counter()
        if wait > 0:
            time.sleep(wait)
        rec.pulses(_block(first, blocks[(first // BLOCK) % len(blocks)], prf), None)
        first += BLOCK
    streamed = time.perf_counter() - t0
    rec.finish({})
    elapsed = time.perf_counter() - t0
    shot_bytes = blocks[0][0].nbytes
    return {
        "stream_mb_per_s": prf * shot_bytes / 1e6,
        "pulses": first,
        "record_written": rec.written,
        "record_dropped": rec.dropped,
        "stream_seconds": streamed,
        "close_seconds": elapsed - streamed,
        "written_mb_per_s": rec.written * shot_bytes / 1e6 / elapsed,
        "seconds_with_close": elapsed,
    }


def _as_fast(config: Config, path: Path, seconds: float, blocks) -> dict:
    prf = config.geometry.prf_hz
    rec = ShotRecorder(path, config)
    t0 = time.perf_counter()
    first = 0
    while time.perf_counter() - t0 < seconds:
        if not rec.has_room(blocks[0].nbytes):  # the queue is full: wait, never drop
            time.sleep(0.001)
            continue
        rec.pulses(_block(first, blocks[(first // BLOCK) % len(blocks)], prf), None)
        first += BLOCK
    rec.finish({})
    cached = time.perf_counter() - t0
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)
    synced = time.perf_counter() - t0
    mb = rec.written * blocks[0][0].nbytes / 1e6
    return {
        "pulses": rec.written,
        "record_dropped": rec.dropped,
        "mb": mb,
        "page_cache_mb_per_s": mb / cached,
        "disk_mb_per_s": mb / synced,
    }


def bench_recording(config: Config, folder: str | Path | None = None, seconds: float = 3.0):
    """The two measurements (module docstring) in a temporary folder inside ``folder``
    (default: the current folder, the disk a recording would go to), removed afterwards."""
    blocks = _blocks(config)
    where = Path(tempfile.mkdtemp(prefix=".rtsar-bench-record-", dir=folder or "."))
    try:
        paced = _paced(config, where / "paced.h5", seconds, blocks)
        (where / "paced.h5").unlink()
        fast = _as_fast(config, where / "fast.h5", seconds, blocks)
    finally:
        shutil.rmtree(where, ignore_errors=True)
    return {"folder": str(Path(folder or ".").resolve()), "paced": paced, "as_fast": fast}


def recording_lines(name: str, row: dict) -> list[str]:
    """The row in words, for ``rtsar bench``'s output."""
    p, f = row["paced"], row["as_fast"]
    return [
        f"\nRaw recording (run --record) at {name} on the disk of {row['folder']}",
        f"paced at the PRF ({p['stream_mb_per_s']:.0f} MB/s) for {p['stream_seconds']:.1f} s: "
        f"{p['record_written']:,} of {p['pulses']:,} shots recorded, record_dropped "
        f"{p['record_dropped']:,}",
        f"  the queue drained and the file closed {p['close_seconds']:.2f} s after the last "
        f"shot: {p['written_mb_per_s']:.0f} MB/s from the first shot to the close",
        f"as fast as it takes them: {f['page_cache_mb_per_s']:.0f} MB/s into the page cache, "
        f"{f['disk_mb_per_s']:.0f} MB/s to the disk (fsync at the end; {f['mb']:.0f} MB)",
    ]
