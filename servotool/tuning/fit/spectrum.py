"""The spectrum of a sampled signal and its peaks, with what the sampling lets it see.

A line samples at a few tens to a few hundred per second, unevenly: the samples are brought onto an even grid at
their median interval, the trend removed and a Hann window applied before the transform. Nothing above the Nyquist
limit (half the sampling rate) is visible; a resonance above it shows folded below it, so a peak close to the limit
is not taken as the machine's own frequency (RESOLVABLE_SHARE).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

PEAK_FACTOR = 6.0  # a peak stands this many times above the spectrum's median amplitude ...
PEAK_SHARE = 0.15  # ... and at least this share of the highest peak
MIN_BINS = 2  # a peak lies at least this many frequency bins above 0 Hz (the motion itself, not a ringing)
RESOLVABLE_SHARE = 0.8  # a peak up to this share of the Nyquist limit counts as resolved (beyond: perhaps folded)
MAX_PEAKS = 4


@dataclass(frozen=True)
class Peak:
    hz: float
    amplitude: float  # in the signal's unit (the sine's amplitude)
    resolvable: bool  # within RESOLVABLE_SHARE of the Nyquist limit and MIN_BINS above 0 Hz


@dataclass(frozen=True)
class Spectrum:
    hz: np.ndarray
    amplitude: np.ndarray
    rate_hz: float  # samples per second (the median interval's)
    nyquist_hz: float
    resolution_hz: float  # one frequency bin: 1 / the signal's length
    peaks: tuple[Peak, ...]


def spectrum(t: np.ndarray, x: np.ndarray) -> Spectrum | None:
    """The amplitude spectrum of x sampled at times t (s) and its peaks, highest first; None under 8 samples."""
    t, x = np.asarray(t, dtype=float), np.asarray(x, dtype=float)
    if t.size < 8 or t[-1] <= t[0]:
        return None
    dt = float(np.median(np.diff(t)))
    if dt <= 0:
        return None
    grid = np.arange(t[0], t[-1], dt)
    y = np.interp(grid, t, x)
    y = y - np.polyval(np.polyfit(grid - grid[0], y, 1), grid - grid[0])
    window = np.hanning(y.size)
    amp = 2.0 * np.abs(np.fft.rfft(y * window)) / max(float(np.sum(window)), 1e-12)
    hz = np.fft.rfftfreq(y.size, dt)
    rate, nyquist = 1.0 / dt, 0.5 / dt
    resolution = 1.0 / (y.size * dt)
    return Spectrum(hz, amp, rate, nyquist, resolution, _peaks(hz, amp, nyquist))


def _peaks(hz: np.ndarray, amp: np.ndarray, nyquist: float) -> tuple[Peak, ...]:
    if amp.size < MIN_BINS + 3:
        return ()
    floor = float(np.median(amp[MIN_BINS:]))
    inner = np.arange(MIN_BINS, amp.size - 1)
    local = inner[(amp[inner] >= amp[inner - 1]) & (amp[inner] > amp[inner + 1])]
    if local.size == 0:
        return ()
    top = float(np.max(amp[local]))
    found = [i for i in local if amp[i] > PEAK_FACTOR * floor and amp[i] >= PEAK_SHARE * top]
    found.sort(key=lambda i: -amp[i])
    return tuple(
        Peak(_refined(hz, amp, i), float(amp[i]), bool(hz[i] <= RESOLVABLE_SHARE * nyquist)) for i in found[:MAX_PEAKS]
    )


def _refined(hz: np.ndarray, amp: np.ndarray, i: int) -> float:
    """A peak's frequency between bins (a parabola through the bin and its neighbours' log amplitudes)."""
    a, b, c = (float(np.log(max(v, 1e-300))) for v in amp[i - 1 : i + 2])
    den = a - 2 * b + c
    shift = 0.5 * (a - c) / den if den < 0 else 0.0
    return float(hz[i] + max(-0.5, min(0.5, shift)) * (hz[1] - hz[0]))
