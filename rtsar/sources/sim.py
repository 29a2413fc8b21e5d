"""The simulator as a live source: a scene's shots released at its PRF (the built-in demo)."""

from __future__ import annotations

import atexit
import subprocess
import time
from collections.abc import Iterator
from dataclasses import replace

import numpy as np

from ..child import module_argv
from ..params import PulsedChirp
from ..scene import Scene, Simulator
from ..scene.tones import kernels_cached
from .base import ShotBatch, Source
from .pacing import Pacer, next_release, release_chunk
from .sim_process import ShotFeed

WARM_TIMEOUT_S = 300.0  # the warming process; past it, the kernels are compiled here


def _end(process: subprocess.Popen) -> None:
    """Stop a warming process that is still running, and reap it."""
    if process.poll() is None:
        process.kill()
        process.wait()


class SimSource(Source):
    """Shots of ``scene`` on the absolute schedule t0 + p/PRF; arrival time = scheduled time.

    Shots are generated ahead and released in chunks (up to 8 pulses, at most 1 ms); arrival
    is when the instrument would have delivered it, so the wait for its chunk counts as latency.
    If generation falls behind the schedule, shots go out late (their arrival stays the
    scheduled time) and ``counters["late_releases"]`` counts the chunks; the next release then
    holds every shot already due, up to 64 (rtsar.sources.pacing.next_release), so the source
    catches up rather than staying behind one small chunk at a time.  ``separate``: the shots
    are made in a process of their own, as an instrument's are (rtsar.sources.sim_process;
    ``rtsar run``), not in this one beside the stages; the same shots, bit for bit.
    """

    live = True

    def __init__(
        self,
        scene: Scene,
        pulses: int | None = None,
        chunk: int | None = None,
        warm_from: str | None = None,
        separate: bool = False,
    ):
        super().__init__()
        # warm_from: the scene's file; where numba's cache lacks the simulator's kernels, a
        # process of its own compiles them now (rtsar.scene.warm) while the caller prepares
        # the rest, and prepare() waits for it.
        self._warming = None
        if warm_from is not None:
            if kernels_cached(isinstance(scene.config.waveform, PulsedChirp)) is False:
                cmd = module_argv("rtsar.scene.warm", str(warm_from))
                self._warming = subprocess.Popen(
                    cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL
                )
                atexit.register(_end, self._warming)  # a run that fails first leaves none
        self.scene = scene
        self.sim = Simulator(scene)
        self.prf_hz = scene.config.geometry.prf_hz
        self.total = scene.pulses if pulses is None else min(int(pulses), scene.pulses)
        self.chunk = chunk or release_chunk(self.prf_hz)
        self.released = 0
        self.counters = {"late_releases": 0}
        self._aux_names: tuple[str, ...] | None = None
        self.description = f"simulated scene '{scene.name}' at {self.prf_hz:g} Hz"
        self._feed = ShotFeed(scene, self.total, lambda: self._stop) if separate else None

    def aux_channels(self) -> tuple[str, ...]:
        """The auxiliary channels the scene's effects make (one pulse of a separate simulator
        says which: effects declare them only by making them)."""
        if self._aux_names is None:
            _, aux = Simulator(replace(self.scene, pulses=1)).block_with_aux(1)
            self._aux_names = tuple(sorted(aux))
        return self._aux_names

    @property
    def warming(self) -> bool:
        """Whether a process is compiling the simulator's kernels (``warm_from``)."""
        return self._warming is not None and self._warming.poll() is None

    def wait_warm(self, say=None) -> None:
        """Wait for the warming process (``warm_from``) to end, if there is one: what must be
        timed alone (the OpenCL survey) is not timed beside it.  ``say``: told of the wait."""
        if self._warming is not None:
            if say is not None and self._warming.poll() is None:
                say(
                    "numba is compiling the simulator's kernels, in a process of their own: the "
                    "first run of this installation (seconds; cached for later runs)"
                )
            try:
                self._warming.wait(timeout=WARM_TIMEOUT_S)
            except subprocess.TimeoutExpired:  # then compiled here, as without it
                _end(self._warming)
            self._warming = None

    def prepare(self) -> None:
        """Ready the simulator's kernels before the schedule starts (rtsar.app.live calls it
        while it says "preparing …"): loaded from numba's cache once the warming process
        (``warm_from``) has compiled them, else compiled here."""
        self.wait_warm()
        if self._feed is not None:
            self._feed.start()  # its kernels load there, from the cache the warming filled
        else:
            self.sim.prepare()

    def cost_per_pulse_s(self, places: int = 5, shots: int = 16) -> float:
        """Seconds of synthesis a shot on this machine now, the mean over ``places`` spots
        spread along the run (the cost follows the scatterers in view: the demo's is 85 µs a
        shot at its start, about 180 µs over its pass), each the best of 2 blocks of ``shots``
        by a simulator of its own (the stream's is not advanced).  The granularity counts it
        (rtsar.stream.granularity.StageCosts).  0 where the shots are made in a process of
        their own (``separate``): that work is not this process's, as an instrument's is not."""
        if self._feed is not None:
            return 0.0
        step = self.scene.config.geometry.along_track_step_m
        costs = []
        for k in range(places):
            first = int(k * max(self.total - 2 * shots, 0) / max(places - 1, 1))
            at = self.scene.start_along_track_m + first * step
            sim = Simulator(replace(self.scene, start_along_track_m=at, pulses=3 * shots))
            sim.block_with_aux(1)  # its first call sets up what the later ones reuse
            best = float("inf")
            for _ in range(2):
                t0 = time.perf_counter()
                sim.block_with_aux(shots)
                best = min(best, (time.perf_counter() - t0) / shots)
            costs.append(best)
        return float(np.mean(costs))

    def __iter__(self) -> Iterator[ShotBatch]:
        pacer = Pacer(self.prf_hz)
        p = 0
        try:
            while p < self.total and not self._stop:
                n = next_release(pacer, p, self.chunk, self.total - p)
                if self._feed is None:
                    samples, aux = self.sim.block_with_aux(n)
                elif (made := self._feed.take(n)) is not None:
                    samples, aux = made
                else:  # closed while waiting for the shots
                    break
                due = pacer.wait(p + n - 1, lambda: self._stop)
                if time.perf_counter() - due > 1e-3:
                    self.counters["late_releases"] += 1
                idx = np.arange(p, p + n)
                times = idx / self.prf_hz
                yield ShotBatch(idx, times, pacer.t0 + times, samples, aux)
                p += n
                self.released = p
        finally:
            if self._feed is not None:  # the shots' process ends with the stream
                self._feed.close()
