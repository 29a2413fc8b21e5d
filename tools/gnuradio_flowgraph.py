"""A GNU Radio flowgraph that streams an rtsar recording to ``rtsar run --zmq-in``.

Run it with a Python that has GNU Radio (Debian: ``apt install gnuradio``, then the system
``python3``); it does not import rtsar.  Its input is a SigMF recording written by
``rtsar export REC.h5 --sigmf OUT`` (the shots as ``cf32_le``, ``rtsar:samples_per_shot`` and
``rtsar:prf_hz`` in the metadata):

    rtsar simulate scene.toml -o rec.h5 && rtsar export rec.h5 --sigmf rec
    rtsar run --zmq-in tcp://127.0.0.1:5600 --scene scene.toml --duration 5 -o img.h5 &
    /usr/bin/python3 tools/gnuradio_flowgraph.py rec.sigmf-meta --endpoint tcp://127.0.0.1:5600 \
        --start-delay 3

(docs/pages/guide/recordings.md, "GNU Radio", runs exactly this.)  Without GNU Radio the script
says in one line what to install, and exits with status 2.

Flowgraph: File Source → Throttle (the recording's PRF × --rate) → either Stream to Tagged
Stream (``packet_len`` = samples per shot) → ZMQ PUB Sink with pass tags (``--mode tagged``,
the default: a flat stream cut by tags), or Stream to Vector → ZMQ PUB Sink with vlen = samples
per shot (``--mode vector``).  The sink binds; data starts ``--start-delay`` seconds later so a
subscriber that connects meanwhile sees the first shot (a PUB socket drops what nobody hears).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

INSTALL = (
    "install GNU Radio (Debian/Ubuntu: sudo apt-get install gnuradio; elsewhere: "
    "https://wiki.gnuradio.org/index.php/InstallingGR) and run this script with the Python "
    "that has it (Debian: /usr/bin/python3)"
)


def gnuradio():
    """GNU Radio's blocks, gr and zeromq modules, or exit with one line saying what to install."""
    try:
        from gnuradio import blocks, gr, zeromq
    except ImportError as exc:
        print(
            f"gnuradio_flowgraph.py: {sys.executable} cannot import GNU Radio ({exc}): {INSTALL}",
            file=sys.stderr,
        )
        raise SystemExit(2) from None
    return blocks, gr, zeromq


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("sigmf", help="OUT.sigmf-meta written by `rtsar export --sigmf`")
    p.add_argument("--endpoint", default="tcp://127.0.0.1:5600", help="PUB sink address")
    p.add_argument("--mode", choices=("tagged", "vector"), default="tagged")
    p.add_argument("--rate", type=float, default=1.0, help="speed-up of the PRF (default 1)")
    p.add_argument("--start-delay", type=float, default=1.0, help="seconds (default 1)")
    args = p.parse_args(argv)
    blocks, gr, zeromq = gnuradio()
    meta_path = Path(args.sigmf)
    meta = json.loads(meta_path.read_text())["global"]
    data = meta_path.with_name(meta_path.name.replace(".sigmf-meta", ".sigmf-data"))
    s = int(meta["rtsar:samples_per_shot"])
    prf = float(meta["rtsar:prf_hz"])
    size = gr.sizeof_gr_complex
    tb = gr.top_block("rtsar recording → ZMQ")
    src = blocks.file_source(size, str(data), False)
    throttle = blocks.throttle(size, prf * s * args.rate)
    if args.mode == "tagged":
        cut = blocks.stream_to_tagged_stream(size, 1, s, "packet_len")
        sink = zeromq.pub_sink(size, 1, args.endpoint, 100, True, -1)
    else:
        cut = blocks.stream_to_vector(size, s)
        sink = zeromq.pub_sink(size, s, args.endpoint, 100, False, -1)
    tb.connect(src, throttle, cut, sink)
    time.sleep(args.start_delay)
    t0 = time.perf_counter()
    tb.start()
    tb.wait()
    time.sleep(0.5)  # let the last messages leave the socket
    tb.stop()
    shots = data.stat().st_size // (size * s)
    print(f"sent {shots} shots of {s} samples ({args.mode}) in {time.perf_counter() - t0:.1f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
