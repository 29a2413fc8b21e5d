"""A fake instrument: the shots of a recording or a scene sent as rtsar frames at the PRF.

    python tools/fake_instrument.py --listen 127.0.0.1:7000              # demo scene, TCP
    python tools/fake_instrument.py --pty --recording REC.h5              # a pseudo-terminal
    python tools/fake_instrument.py --listen 127.0.0.1:7000 --corrupt 0.01 --drop 0.001

The processor reads it as ``socket://127.0.0.1:7000`` or as the slave path printed by --pty
(rtsar.sources.serial.SerialSource).  Shot n goes out as one frame (rtsar.sources.frame) with
sequence n and timestamp n/PRF, at t0 + n/PRF, t0 being when the reader connected plus
--start-delay: an absolute schedule, so a late frame does not delay the ones after it.
The start delay is needed because pyserial discards what arrived while it was opening the port.

Link faults, each drawn per frame with --seed: --drop (not sent), --corrupt (1 to 4 bytes flipped
after the sync word, so the receiver sees the frame and rejects it by CRC), --duplicate (sent
twice).  The tool serves one reader, then prints a summary; Ctrl-C stops it early.
"""

from __future__ import annotations

import argparse
import os
import select
import signal
import socket
import sys
import threading
import time
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass, field

import numpy as np

from rtsar.scene import DEMO_SCENE, Scene, Simulator, load_scene
from rtsar.sinks.io import open_recording
from rtsar.sources.channel_map import ChannelMap
from rtsar.sources.frame import SAMPLE_TYPES, SYNC, encode_frame

CI16_PEAK = 8192  # --scale auto for ci16: the first block's largest |I| or |Q| maps to this


@dataclass
class EmitSummary:
    shots: int = 0  # shots taken from the source (sequence numbers used)
    sent: int = 0  # frames written, duplicates included
    corrupted: int = 0
    dropped: int = 0
    duplicated: int = 0
    late: int = 0  # frames written more than one PRI after their due time
    max_late_s: float = 0.0
    corrupted_seqs: list[int] = field(default_factory=list)
    dropped_seqs: list[int] = field(default_factory=list)
    stopped: str | None = None  # why it ended before the last shot, if it did

    def line(self) -> str:
        text = (
            f"{self.shots} shots: {self.sent} frames sent, {self.corrupted} corrupted, "
            f"{self.dropped} dropped, {self.duplicated} duplicated; {self.late} late "
            f"(worst {1e3 * self.max_late_s:.1f} ms)"
        )
        return text + (f"; stopped: {self.stopped}" if self.stopped else "")


def emit_frames(
    write: Callable[[bytes], object],
    shots: Iterable[np.ndarray],
    prf_hz: float,
    *,
    sample_type: str = "cf32",
    scale: float = 1.0,
    corrupt: float = 0.0,
    drop: float = 0.0,
    duplicate: float = 0.0,
    seed: int = 0,
    start_delay_s: float = 0.0,
    stop: threading.Event | None = None,
    first_seq: int = 0,
) -> EmitSummary:
    """Write one frame per shot with ``write`` on the schedule t0 + n/prf_hz; return the tally.

    ``shots`` yields blocks [pulse, sample]; ``scale`` multiplies the samples before encoding;
    shot n carries the sequence number ``first_seq`` + n.
    Ends early (``summary.stopped``) when ``stop`` is set or ``write`` raises OSError (the
    reader went away).
    """
    if not prf_hz > 0:
        raise ValueError(f"prf_hz must be > 0, got {prf_hz!r}")
    for name, p in (("corrupt", corrupt), ("drop", drop), ("duplicate", duplicate)):
        if not 0.0 <= p <= 1.0:
            raise ValueError(f"{name} must be a fraction in [0, 1], got {p!r}")
    stop = stop or threading.Event()
    rng = np.random.default_rng(seed)
    out = EmitSummary()
    period = 1.0 / prf_hz
    t0 = time.perf_counter() + start_delay_s
    n = 0
    try:
        for block in shots:
            for samples in np.atleast_2d(block):
                u_drop, u_corrupt, u_dup = rng.random(3)
                seq = first_seq + n
                frame = encode_frame(seq, round(seq * 1e9 / prf_hz), samples * scale, sample_type)
                due = t0 + n * period
                n += 1
                out.shots = n
                if u_drop < drop:
                    out.dropped += 1
                    out.dropped_seqs.append(seq)
                    continue
                if u_corrupt < corrupt:
                    frame = _flip_bytes(frame, rng)
                    out.corrupted += 1
                    out.corrupted_seqs.append(seq)
                wait = due - time.perf_counter()
                if wait > 0 and stop.wait(wait):
                    out.stopped = "stopped"
                    return out
                if stop.is_set():
                    out.stopped = "stopped"
                    return out
                late = -wait
                if late > period:
                    out.late += 1
                out.max_late_s = max(out.max_late_s, late)
                write(frame)
                out.sent += 1
                if u_dup < duplicate:
                    write(frame)
                    out.sent += 1
                    out.duplicated += 1
    except OSError as exc:
        out.stopped = f"reader gone ({exc})"
    return out


def _flip_bytes(frame: bytes, rng: np.random.Generator) -> bytes:
    """``frame`` with 1 to 4 distinct bytes after the sync word XORed with non-zero values."""
    b = bytearray(frame)
    k = min(int(rng.integers(1, 5)), len(b) - len(SYNC))
    where = len(SYNC) + rng.choice(len(b) - len(SYNC), size=k, replace=False)
    for i, x in zip(where, rng.integers(1, 256, size=k), strict=True):
        b[i] ^= int(x)
    return bytes(b)


# -- where the shots come from --------------------------------------------------------------
def scene_shots(scene: Scene, pulses: int | None = None, block: int = 1) -> Iterator[np.ndarray]:
    """The scene's simulated shots in blocks of ``block`` (all of them by default): [pulse,
    sample], or [pulse, frame channel, sample] when its effects add channels."""
    sim = Simulator(scene)
    cmap = ChannelMap.for_scene(scene)
    left = scene.pulses if pulses is None else min(pulses, scene.pulses)
    while left > 0:
        n = min(block, left)
        main, aux = sim.block_with_aux(n)
        yield main if cmap is None else cmap.pack(main, aux)
        left -= n


def recording_map(recording) -> ChannelMap | None:
    """The channel map of a recording's shots (None: the main channel only)."""
    if not recording.channels:
        return None
    widths = {k: ds.shape[1] for k, ds in recording.channels.items()}
    return ChannelMap.for_channels(recording.config.waveform.samples_per_shot, widths)


def recording_shots(recording, pulses: int | None = None, block: int = 64) -> Iterator[np.ndarray]:
    """The recording's shots in blocks of ``block`` (all of them by default), every channel
    packed into frame channels by recording_map."""
    cmap = recording_map(recording)
    left = recording.pulses if pulses is None else min(pulses, recording.pulses)
    for shots, aux in recording.batches_with_aux(block, list(recording.channels)):
        if left <= 0:
            break
        yield (shots if cmap is None else cmap.pack(shots, aux))[:left]
        left -= len(shots)


# -- how they are served --------------------------------------------------------------------
def parse_address(text: str) -> tuple[str, int]:
    host, sep, port = text.rpartition(":")
    if not sep or not host or not port.isdigit() or not 0 <= int(port) < 65536:
        raise ValueError(f"expected HOST:PORT (e.g. 127.0.0.1:7000), got {text!r}")
    return host.strip("[]"), int(port)


def listen(address: str) -> socket.socket:
    """A TCP server socket on HOST:PORT (port 0: any free port, see ``getsockname()``)."""
    host, port = parse_address(address)
    return socket.create_server((host, port))


def serve_tcp(
    server: socket.socket,
    shots: Iterable[np.ndarray],
    prf_hz: float,
    stop: threading.Event | None = None,
    start_delay_s: float = 0.2,
    **options,
) -> EmitSummary:
    """Wait for one reader on ``server``, send it the frames, close the connection."""
    stop = stop or threading.Event()
    server.settimeout(0.2)  # to notice ``stop`` while waiting
    while True:
        try:
            conn, _ = server.accept()
            break
        except TimeoutError:
            if stop.is_set():
                return EmitSummary(stopped="stopped before a reader connected")
    with conn:
        conn.settimeout(None)
        out = emit_frames(
            conn.sendall, shots, prf_hz, start_delay_s=start_delay_s, stop=stop, **options
        )
        try:
            conn.shutdown(socket.SHUT_WR)
        except OSError:
            pass  # the reader has gone already
    return out


class Pty:
    """A pseudo-terminal whose slave end (``path``) the reader opens as a serial port (POSIX).

    Whether a reader has the slave open is seen as the absence of POLLHUP on the master (Linux).
    """

    def __init__(self):
        import tty  # POSIX only: imported here so that --listen works everywhere

        self.master, slave = os.openpty()
        tty.setraw(slave)
        self.path = os.ttyname(slave)
        os.close(slave)
        os.set_blocking(self.master, False)
        self._poll = select.poll()
        self._poll.register(self.master, select.POLLOUT | select.POLLHUP)

    def _events(self, timeout_s: float) -> int:
        return sum(ev for _, ev in self._poll.poll(1e3 * timeout_s))

    def reader_present(self) -> bool:
        return not self._events(0) & select.POLLHUP

    def wait_reader(self, stop: threading.Event, present: bool = True, timeout_s=None) -> bool:
        """Wait until a reader has the slave open (or, ``present=False``, has closed it)."""
        end = None if timeout_s is None else time.perf_counter() + timeout_s
        while not stop.is_set() and (end is None or time.perf_counter() < end):
            if self.reader_present() == present:
                return True
            time.sleep(0.05)
        return False

    def write(self, data: bytes) -> None:
        view = memoryview(data)
        while view:
            events = self._events(1.0)
            if events & select.POLLHUP:
                raise BrokenPipeError("the reader closed the pseudo-terminal")
            if events & select.POLLOUT:
                try:
                    view = view[os.write(self.master, view) :]
                except BlockingIOError:
                    pass

    def close(self) -> None:
        os.close(self.master)


def serve_pty(
    pty: Pty,
    shots: Iterable[np.ndarray],
    prf_hz: float,
    stop: threading.Event | None = None,
    start_delay_s: float = 0.2,
    linger_s: float = 2.0,
    **options,
) -> EmitSummary:
    """Wait for a reader on ``pty``, send it the frames; keep the master open until the reader
    closes or ``linger_s`` has passed (closing it earlier would discard what is unread)."""
    stop = stop or threading.Event()
    if not pty.wait_reader(stop):
        return EmitSummary(stopped="stopped before a reader connected")
    out = emit_frames(pty.write, shots, prf_hz, start_delay_s=start_delay_s, stop=stop, **options)
    pty.wait_reader(stop, present=False, timeout_s=linger_s)
    return out


# -- command line -----------------------------------------------------------------------------
def _fraction(text: str) -> float:
    x = float(text)
    if not 0.0 <= x <= 1.0:
        raise argparse.ArgumentTypeError(f"must be a fraction in [0, 1], got {text}")
    return x


def _positive(kind):
    def parse(text: str):
        x = kind(text)
        if not x > 0:
            raise argparse.ArgumentTypeError(f"must be > 0, got {text}")
        return x

    return parse


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    src = ap.add_mutually_exclusive_group()
    src.add_argument("--recording", metavar="REC.h5", help="send the shots of this recording")
    src.add_argument(
        "--scene", metavar="SCENE.toml", help="simulate this scene (default: the built-in demo)"
    )
    out = ap.add_mutually_exclusive_group(required=True)
    out.add_argument("--listen", metavar="HOST:PORT", help="serve one TCP reader on this address")
    out.add_argument("--pty", action="store_true", help="open a pseudo-terminal, print its path")
    ap.add_argument(
        "--prf", type=_positive(float), metavar="HZ", help="frame rate (default: the config's PRF)"
    )
    ap.add_argument(
        "--pulses", type=_positive(int), metavar="N", help="send at most N shots (default: all)"
    )
    ap.add_argument(
        "--sample-type",
        choices=sorted(SAMPLE_TYPES),
        default="cf32",
        help="cf32: float32 I,Q (default); ci16: int16 I,Q, half the bytes (see --scale)",
    )
    ap.add_argument(
        "--scale",
        type=_positive(float),
        help="multiply the samples by this (default: 1 for cf32; for ci16, the first block's "
        f"largest |I| or |Q| becomes {CI16_PEAK})",
    )
    for flag, what in (
        ("--corrupt", "flip 1 to 4 random bytes in this fraction of the frames"),
        ("--drop", "do not send this fraction of the frames"),
        ("--duplicate", "send this fraction of the frames twice"),
    ):
        ap.add_argument(flag, type=_fraction, default=0.0, metavar="FRACTION", help=what)
    ap.add_argument("--seed", type=int, default=0, help="seed of the link faults (default 0)")
    ap.add_argument(
        "--start-delay",
        type=float,
        default=0.2,
        metavar="S",
        help="wait this long after the reader connects before the first frame (default 0.2)",
    )
    args = ap.parse_args(argv)

    rec = server = None
    try:
        if args.listen:  # bound first: a reader connecting while the scene loads is queued
            try:
                server = listen(args.listen)
            except OSError as exc:
                raise ValueError(f"cannot listen on {args.listen}: {exc}") from None
        if args.recording:
            rec = open_recording(args.recording)
            cfg, name, cmap = rec.config, args.recording, recording_map(rec)
            shots = recording_shots(rec, args.pulses)
        else:
            scene = load_scene(args.scene or DEMO_SCENE)
            cfg, name, cmap = scene.config, f"scene '{scene.name}'", ChannelMap.for_scene(scene)
            shots = scene_shots(scene, args.pulses)
        if cmap is not None:
            name += f", channels {cmap.text} (rtsar run --serial … --channel-map {cmap.text})"
        return _serve(args, cfg, name, shots, server)
    except ValueError as exc:
        print(f"fake_instrument: {exc}", file=sys.stderr)
        return 2
    finally:
        if rec is not None:
            rec.close()
        if server is not None:
            server.close()


def _serve(args, cfg, name: str, shots: Iterator[np.ndarray], server=None) -> int:
    first = next(shots, None)
    if first is None:
        raise ValueError("no shots to send")
    blocks = _chain(first, shots)
    prf = args.prf or cfg.geometry.prf_hz
    scale = args.scale
    if scale is None:
        scale = 1.0
        peak = max(np.abs(first.real).max(), np.abs(first.imag).max())
        if args.sample_type == "ci16" and peak > 0:
            scale = CI16_PEAK / peak
    options = dict(
        sample_type=args.sample_type,
        scale=scale,
        corrupt=args.corrupt,
        drop=args.drop,
        duplicate=args.duplicate,
        seed=args.seed,
        start_delay_s=args.start_delay,
    )
    stop = threading.Event()
    signal.signal(signal.SIGINT, lambda *_: stop.set())
    what = (
        f"{name}: {cfg.waveform.samples_per_shot} samples/shot, {args.sample_type} "
        f"(scale {scale:g}), {prf:g} Hz"
    )
    if server is not None:
        host, port = server.getsockname()[:2]
        print(f"{what}; waiting for a reader on socket://{host}:{port}", flush=True)
        summary = serve_tcp(server, blocks, prf, stop, **options)
    else:
        pty = Pty()
        print(f"{what}; waiting for a reader on {pty.path}", flush=True)
        try:
            summary = serve_pty(pty, blocks, prf, stop, **options)
        finally:
            pty.close()
    print(summary.line())
    return 0


def _chain(first, rest):
    yield first
    yield from rest


if __name__ == "__main__":
    sys.exit(main())
