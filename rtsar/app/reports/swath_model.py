"""What swath processes cost, and where they would pay: a model from measured per-pulse costs.

Not a test.  ``--swath-workers K`` (rtsar.stream.swath) sends every pulse block to K worker
processes; each runs the whole AO lens (the range FFT needs every sample) and the CCD of its
1/K of the range bins, and sends its lines back.  Against one process, K workers add K - 1
lenses and the transfers.  This report measures, in one run on this machine, the CPU time per
pulse of each piece with one thread (numba and the OpenCL driver limited to one core), at the
preset's micro-batch, interleaved in rounds (each its best round):

* ``t_lens``: the AO lens, whole pulses (every worker pays it);
* ``t_ccd(1/K)``: the correlator of 1/K of the range bins (K = 1, 2, 4, 8);
* ``t_in``: one pulse block through a ZeroMQ PUSH/PULL pair on loopback (send + receive), per
  pulse and per worker; ``t_out(1/K)``: the lines of 1/K of the bins back;

and models the throughput of K workers, each on ``c`` cores of its own host (the coordinator on
its own), against one process on one such host:

    one process:   c / (t_lens + t_ccd(1))
    K workers:     min( c / (t_lens + t_ccd(1/K) + t_in + t_out(1/K)),   [each worker]
                        1 / (K t_in + K t_out(1/K)) )                     [the coordinator]

(perfect use of the ``c`` cores of each host, an upper bound for both).  On one host the K
workers share its cores: ``c / (K t_lens + K t_ccd(1/K) + K t_in + K t_out(1/K))``, never more
than one process.  The crossover, the least K on separate hosts that beats one process, is
printed with the measured figures.

    python tools/swath_model.py [--preset psaltis-max] [--correlator nonuniform]
                                [--rounds 3] [--seconds 1] [--json F]
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import time

import numpy as np
import zmq

from ...ccd import processor_correlator
from ...ccd.base import design_mask
from ...lens import make_lens, make_plan
from ...presets import preset


def _one_core() -> None:
    """One thread for numba and PoCL (before they load: numba with the numba correlators,
    PoCL at the first OpenCL call): per-pulse CPU times, not wall times of parallel regions."""
    # its one-thread timings are not this machine's: kept apart from the cached survey
    os.environ.setdefault("RTSAR_CACHE_DIR", tempfile.mkdtemp(prefix="rtsar-swath-model-"))
    os.environ.setdefault("NUMBA_NUM_THREADS", "1")
    os.environ.setdefault("POCL_MAX_PTHREAD_COUNT", "1")
    os.environ.setdefault("OMP_NUM_THREADS", "1")


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="swath_model", description=__doc__.split("\n\n")[0])
    p.add_argument("--preset", default="psaltis-max")
    p.add_argument("--correlator", default="nonuniform")
    p.add_argument("--rounds", type=int, default=3)
    p.add_argument("--seconds", type=float, default=1.0, help="each measurement in a round")
    p.add_argument("--json", metavar="F")
    return p


def _per_pulse(call, batch: int, seconds: float) -> float:
    """Seconds per pulse of ``call()`` (which handles ``batch`` pulses): the median call."""
    for _ in range(3):
        call()
    times, start = [], time.perf_counter()
    while len(times) < 10 or time.perf_counter() - start < seconds:
        t0 = time.perf_counter()
        call()
        times.append(time.perf_counter() - t0)
    return float(np.median(times)) / batch


def _transfer(nbytes: int):
    """A callable sending ``nbytes`` through a loopback PUSH/PULL pair and receiving them."""
    ctx = zmq.Context.instance()
    pull = ctx.socket(zmq.PULL)
    port = pull.bind_to_random_port("tcp://127.0.0.1")
    push = ctx.socket(zmq.PUSH)
    push.connect(f"tcp://127.0.0.1:{port}")
    payload = np.zeros(nbytes, np.uint8)

    def call():
        push.send_multipart([b"block", b"{}", payload], copy=False)
        pull.recv_multipart(copy=False)

    return call


def measure(args) -> dict:
    cfg = preset(args.preset).with_processor(correlator=args.correlator)
    plan = make_plan(cfg)
    b = cfg.processor.micro_batch
    S, bins = plan.samples_per_shot, plan.bin_count
    rng = np.random.default_rng(0)
    shots = (rng.standard_normal((b, S)) + 1j * rng.standard_normal((b, S))).astype(np.complex64)
    lens = make_lens(plan, "auto", batch=b)
    lines = lens.compress(shots)
    mask = design_mask(cfg, plan.range_m)
    ks = (1, 2, 4, 8)
    ccds = {k: processor_correlator(cfg.processor, mask[:, : -(-bins // k)]) for k in ks}
    calls = {"t_lens": lambda: lens.compress(shots)}
    for k, ccd in ccds.items():
        part = np.ascontiguousarray(lines[:, : -(-bins // k)])
        calls[f"t_ccd(1/{k})"] = lambda c=ccd, x=part: c.push(x)
    calls["t_in"] = _transfer(b * S * 8)
    for k in ks:
        calls[f"t_out(1/{k})"] = _transfer(b * -(-bins // k) * 8)
    best = dict.fromkeys(calls, float("inf"))
    for _ in range(args.rounds):
        for name, call in calls.items():
            best[name] = min(best[name], _per_pulse(call, b, args.seconds / args.rounds))
    for ccd in ccds.values():
        ccd.close()
    return {
        "preset": args.preset,
        "correlator": args.correlator,
        "micro_batch": b,
        "lens": lens.choice,
        "seconds_per_pulse": best,
    }


def model(t: dict, cores: int = 2) -> list[dict]:
    """Modelled pulses/s of one process and of K workers (separate hosts, one host) on
    ``cores`` cores each, from the measured seconds per pulse ``t``."""
    one = cores / (t["t_lens"] + t["t_ccd(1/1)"])
    rows = [{"workers": 1, "separate_hosts": one, "one_host": one, "over_one_process": 1.0}]
    for k in (2, 4, 8):
        worker = t["t_lens"] + t[f"t_ccd(1/{k})"] + t["t_in"] + t[f"t_out(1/{k})"]
        coordinator = k * (t["t_in"] + t[f"t_out(1/{k})"])
        hosts = min(cores / worker, 1.0 / coordinator)
        rows.append(
            {
                "workers": k,
                "separate_hosts": hosts,
                "one_host": cores / (k * worker),
                "over_one_process": hosts / one,
            }
        )
    return rows


def main(argv=None) -> int:
    _one_core()
    args = _parser().parse_args(argv)
    result = measure(args)
    t = result["seconds_per_pulse"]
    print(
        f"{args.preset}, {args.correlator} correlator, batch {result['micro_batch']}, one core "
        f"each; lens: {result['lens']}"
    )
    for name, value in t.items():
        print(f"  {name:12} {value * 1e6:9.2f} µs/pulse")
    rows = model(t)
    result["model_2_cores"] = rows
    print("\nmodel, 2 cores per host (pulses/s; one process = 1):")
    print(f"  {'K':>2} {'K hosts':>12} {'one host':>12} {'K hosts / one process':>22}")
    for r in rows:
        print(
            f"  {r['workers']:>2} {r['separate_hosts']:12,.0f} {r['one_host']:12,.0f} "
            f"{r['over_one_process']:22.2f}"
        )
    wins = [r["workers"] for r in rows[1:] if r["over_one_process"] > 1]
    crossover = (
        f"K = {wins[0]} workers on separate hosts beat one process"
        if wins
        else "no K up to 8 beats one process"
    )
    print(f"\ncrossover: {crossover}; on one host K workers never do (every worker pays the lens)")
    result["crossover"] = crossover
    if args.json:
        with open(args.json, "w", encoding="utf-8") as f:
            json.dump(result, f, indent=1)
    return 0


if __name__ == "__main__":
    sys.exit(main())
