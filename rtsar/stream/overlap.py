"""The "overlapped" stage layout: lens and CCD in one thread, the device computing batch k + 1
while the CCD correlates batch k.

On two cores a second thread for the CCD costs a hand-off per batch and two thread pools (the
lens driver's and numba's) competing for the same cores; one thread that enqueues the lens
(rtsar.lens.opencl.AOLens.submit, not waited for) and correlates the previous batch meanwhile
keeps both busy with one hand-off less.  Only while shots are waiting: when none is, the batch
in flight is finished at once (latency first).  Without an OpenCL lens, or with a correction or
the AO cell, the lens runs before the CCD (rtsar.stream.engine.StreamProcessor.range_submit).
"""

from __future__ import annotations

import time

from .ingest import regroup_blocks


def overlapped_stage(pipe) -> None:
    """The lens + CCD thread of ``pipe`` (an rtsar.stream.pipeline.Pipeline) in this layout."""
    busy, pending = 0.0, None  # pending: (lines callable, pulse block)
    try:
        while True:
            batches = pipe.q_shots.get_batch(pipe.max_batch, 0 if pending else None)
            t = time.perf_counter()
            if batches == []:  # nothing waiting: finish the batch in flight
                _finish(pipe, pending)
                pending = None
            else:
                for block in regroup_blocks(pipe._ingest(batches), pipe.max_batch):
                    zero = bool(block.flagged.all())
                    job = pipe.engine.range_submit(block.samples, block.aux, zero)
                    _finish(pipe, pending)  # the CCD on the previous batch meanwhile
                    pending = (job, block)
                if batches is None:
                    _finish(pipe, pending)
                    pipe._put_image(pipe._ccd_flush())
            busy += time.perf_counter() - t
            pipe.stats.busy_s["lens+ccd"] = busy
            if batches is None:
                break
    finally:
        pipe.stats.busy_s["lens+ccd"] = busy
        pipe.q_image.close()
        pipe._close_correlators()


def _finish(pipe, pending) -> None:
    if pending is not None:
        job, block = pending
        pipe._put_image(pipe._ccd_step([block.with_samples(job())]))
