"""The physical CCD's charge shift register: real charge, per-exposure full well and blooming.

Psaltis & Wagner 1981, "Description of the processor": each laser pulse exposes every row of the
CCD through the mask, the charge shifts one row, and the row reaching the readout register is a
finished packet.  Here the charge is real (electrons, float64), pixel (k, c) collects
T[k, c]·I_e[c] per exposure (rtsar.physical.carrier eq. P1-P2), and after every exposure a pixel
holding more than the full well is clipped: its excess is drained (anti-blooming gate) or, with
blooming, spills half into each neighbouring row of the same column, repeatedly, until no pixel
is over the well (charge spilling past the top or bottom row is lost).  A circular slot index
replaces the physical shift, as in rtsar.ccd.DirectCorrelator.
"""

from __future__ import annotations

import numba
import numpy as np

# stats[c, :] per column: pixel overflows (pixel-exposures over the well), drained e-, bloomed e-
STAT_OVERFLOWS, STAT_DRAINED_E, STAT_BLOOMED_E = 0, 1, 2


@numba.njit(nogil=True, cache=True)
def _overflow(a, fl, h, full_well, bloom, st):  # pragma: no cover - compiled
    # a[slot]: one column; slot (h + j) % R is physical row R-1-j (j = 0: the bottom row).
    n = a.shape[0]
    for j in range(n):
        s = h + j - n if h + j >= n else h + j
        if a[s] > full_well:
            st[0] += 1.0
            fl[s] = 1
    if bloom:
        for _ in range(4 * n):
            moved = False
            for j in range(n):
                s = h + j - n if h + j >= n else h + j
                x = a[s]
                if x > full_well:
                    half = 0.5 * (x - full_well)
                    a[s] = full_well
                    st[2] += x - full_well
                    moved = True
                    if j > 0:  # the row below (nearer the readout)
                        b = s - 1 if s > 0 else n - 1
                        a[b] += half
                        fl[b] = 1
                    else:
                        st[1] += half
                    if j < n - 1:  # the row above
                        b = s + 1 if s < n - 1 else 0
                        a[b] += half
                        fl[b] = 1
                    else:
                        st[1] += half
            if not moved:
                return
    for j in range(n):  # no blooming (or it did not settle): drain the excess
        s = h + j - n if h + j >= n else h + j
        if a[s] > full_well:
            st[1] += a[s] - full_well
            a[s] = full_well


# Finite inputs only (PhysicalCCD checks them): no NaN/Inf semantics needed, which lets LLVM
# vectorise the running maximum (~15 % faster); products and sums are not reassociated.
@numba.njit(parallel=True, nogil=True, cache=True, fastmath={"nnan", "ninf", "nsz"})
def _expose(acc, t_rev, head, intensity, full_well, bloom, out, out_flags, flags, stats):
    # pragma: no cover - compiled
    # acc[c, slot]: slot (head + j) % R leaves after j more exposures; t_rev[c, j] = T[R-1-j, c].
    # Per exposure b:  acc[c, (head+j) % R] += I[b, c] · T[R-1-j, c] for every j (eq. P1), clip
    # or bloom if a pixel is over the well, then slot head is the finished packet: read, zero,
    # head advances (the shift).
    n = acc.shape[1]
    for c in numba.prange(acc.shape[0]):
        a = acc[c]
        t = t_rev[c]
        fl = flags[c]
        h = head
        for b in range(intensity.shape[0]):
            v = intensity[b, c]
            split = n - h
            peak = 0.0
            for j in range(split):
                x = a[h + j] + v * t[j]
                a[h + j] = x
                peak = max(peak, x)
            for j in range(split, n):
                x = a[h + j - n] + v * t[j]
                a[h + j - n] = x
                peak = max(peak, x)
            if peak > full_well:
                _overflow(a, fl, h, full_well, bloom, stats[c])
            out[b, c] = a[h]
            out_flags[b, c] = fl[h]
            a[h] = 0.0
            fl[h] = 0
            h += 1
            if h == n:
                h = 0


class ShiftRegister:
    """R rows × W columns of charge; ``expose`` adds exposures and returns the packets read out.

    ``transmittance`` is T[k, c] (row k = 0 at the top, where packets enter); ``prefill_e``
    (per column, e- per unit transmittance) fills the register with the steady state of
    exposures of that intensity, i.e. the bias of a CCD that ran before the first pulse.
    """

    def __init__(
        self,
        transmittance: np.ndarray,
        full_well_e: float,
        bloom: bool,
        prefill_e: np.ndarray | float = 0.0,
    ):
        t = np.asarray(transmittance, dtype=np.float64)
        if t.ndim != 2 or t.shape[0] < 2 or not np.all(np.isfinite(t)) or t.min() < 0:
            raise ValueError("transmittance must be a finite, non-negative [rows >= 2, columns]")
        self.rows, self.columns = t.shape
        self.full_well_e = float(full_well_e)
        self.bloom = bool(bloom)
        self._t_rev = np.ascontiguousarray(t[::-1].T)
        # Slot j (j more exposures to go) has received rows 0 .. R-2-j: a cumulative sum.
        before = np.zeros_like(t)
        before[1:] = np.cumsum(t, axis=0)[:-1]  # before[k] = Σ_{k' < k} T[k']
        prefill = np.broadcast_to(np.asarray(prefill_e, dtype=np.float64), (self.columns,))
        self._acc = np.ascontiguousarray((before * prefill)[::-1].T)  # slot j ↔ row R-1-j
        self._flags = np.zeros((self.columns, self.rows), np.int8)
        self._head = 0
        self.stats = np.zeros((self.columns, 3))
        self.exposures = 0
        scratch = np.zeros((1, 2))
        _expose(
            scratch.copy(), scratch.copy(), 0, scratch[:, :1], 1.0, True,
            scratch[:, :1].copy(), np.zeros((1, 1), np.int8), np.zeros((1, 2), np.int8),
            np.zeros((1, 3)),
        )  # fmt: skip

    def expose(self, intensity: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Exposures I[e, c] (e- per unit transmittance) → (packets read out, their flags).

        Packet b of the result left the register at exposure ``self.exposures + b`` (before the
        call); a flag marks a packet that was clipped or received bloomed charge.
        """
        inten = np.ascontiguousarray(intensity, dtype=np.float64)
        if inten.ndim != 2 or inten.shape[1] != self.columns:
            raise ValueError(f"intensity must be [exposures, {self.columns}], got {inten.shape}")
        out = np.empty_like(inten)
        flags = np.zeros(inten.shape, np.int8)
        if len(inten):
            _expose(
                self._acc, self._t_rev, self._head, inten, self.full_well_e, self.bloom,
                out, flags, self._flags, self.stats,
            )  # fmt: skip
        self._head = (self._head + len(inten)) % self.rows
        self.exposures += len(inten)
        return out, flags

    def copy(self) -> ShiftRegister:
        """An independent register in the same state (flush works on one)."""
        new = object.__new__(ShiftRegister)
        new.__dict__.update(self.__dict__)
        new._acc, new._flags, new.stats = self._acc.copy(), self._flags.copy(), self.stats.copy()
        return new
