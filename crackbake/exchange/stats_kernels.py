"""numba kernels for :func:`crackbake.exchange.exrstats.plane_stats`: one pass over a plane
gives its min, max, non-zero count, non-finite count and sum.

numpy took 30 to 60 ms a 4096² plane in several passes (a float64 cast for the mean, two
integer views for a half plane's range, a masked count of its non-zeros), about 0.35 CPU-s of
the README bake's write stage (issue 25).  One kernel per pixel type, each reading the plane
once, in runs of :data:`SEGMENT` texels (a few KB, so a run's second loop reads from cache):

- half: the uint16 bit patterns.  A pattern whose magnitude (the low 15 bits) is 0x7C00 or
  more is an inf or a NaN: counted and skipped.  The range is kept as integer keys in float
  order (the magnitude for a positive pattern, its complement for a negative one, so -0 sits
  just below +0).  The sum is exact: every half is a multiple of 2^-24 below 2^16, so a float64
  sum of a run of 8192 (below 2^29) is exact in any order (the loop may run in vector lanes),
  and each run's sum times 2^24 is an integer, added exactly.  The caller first runs the
  kernel without the finite test (``finite_only``): a plane with an inf or a NaN shows it in
  its extreme keys and is run again with the test.
- float32: the range as integer keys of the bit patterns (sign-magnitude flipped into two's
  complement order, -0 below +0), the finite test on the bits.  The sum is float64 in a fixed
  order: each column's running sum from the top row down (an element-wise add, so the loop
  runs in vector lanes), then the column sums from the left.  The order depends on the
  plane's shape alone, never on threads or the machine's vector width.
- uint32: the integers; the sum exact.
- anything else (float64, other integers: no EXR holds them) widened to float64: as float32,
  comparisons instead of keys.

Exact sums are returned split as ``high * 2^32 + low`` (two int64s that cannot overflow below
2^31 runs) and joined into a Python int by the caller, whose true division is correctly
rounded: a half or uint plane's mean is the nearest double to the exact mean.

A module of its own, imported only where pixels are reduced: ``crackbake inspect`` of a file
with a valid record never imports numba.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from crackbake.jit import light_cache_loads

light_cache_loads()

#: Texels per run: a half run's float64 sum stays exact (8192 * 65504 < 2^29).
SEGMENT = 8192
_LOW = (1 << 32) - 1
#: The key (magnitude pattern) of a half +inf, and of a float32 +inf: at or above it (or at
#: or below its complement) an inf or a NaN.
HALF_INF_KEY = 0x7C00
FLOAT_INF_KEY = 0x7F800000


# The sums run in vector lanes (reassoc): each run's float64 sum is exact (see the module),
# so its order cannot change it.
@njit(cache=True, nogil=True, fastmath={"reassoc"})
def half_stats(bits: np.ndarray, finite_only: bool):
    """One pass over a float16 plane's bit patterns.

    Parameters
    ----------
    bits : (N,) uint16 ndarray
        The plane's texels viewed as uint16.
    finite_only : bool
        Take every texel as finite (no test per texel; the non-finite count is then 0): the
        caller looks at the keys and, when one is an inf's or a NaN's, runs it again with
        False.

    Returns
    -------
    lo, hi : int
        The smallest and largest (finite) pattern as order keys (see the module; lo > hi
        when no texel is finite).  With ``finite_only``, an inf or a NaN gives ``hi >=
        HALF_INF_KEY`` or ``lo <= ~HALF_INF_KEY``.
    nonzero, nonfinite : int
        Texels other than ±0 (infs and NaNs included), texels that are an inf or a NaN.
    sum_high, sum_low : int
        The finite texels' sum times 2^24 is ``sum_high * 2^32 + sum_low``.
    """
    n = bits.size
    # each run's texels as float32 bit patterns: the half's sign, exponent and fraction moved
    # to float32's places, which is the half's value times 2^-112 (a subnormal half a
    # subnormal float32): exact in float64, summed there
    run = np.empty(SEGMENT, np.int32)
    scaled = run.view(np.float32)
    lo = np.int32(0x7FFF)
    hi = np.int32(-0x8000)
    nonzero = np.int64(0)
    nonfinite = np.int64(0)
    high = np.int64(0)
    low = np.int64(0)
    for start in range(0, n, SEGMENT):
        stop = min(n, start + SEGMENT)
        if finite_only:
            # Branch-free and with the run's own counters (int32: a run is 8192 texels), so
            # that LLVM runs the loop in vector lanes: 19 -> 10 ms a 4096² plane.  The key is
            # the magnitude, complemented (xor with all ones) when the sign bit is set.
            seg = bits[start:stop]
            count = np.int32(0)
            run_lo = np.int32(0x7FFF)
            run_hi = np.int32(-0x8000)
            for j in range(stop - start):
                u = np.int32(seg[j])
                m = u & np.int32(0x7FFF)
                count += np.int32(m != 0)
                key = m ^ (np.int32(0) - (u >> np.int32(15)))
                run_lo = min(run_lo, key)
                run_hi = max(run_hi, key)
                run[j] = ((u & np.int32(0x8000)) << np.int32(16)) | (m << np.int32(13))
            nonzero += count
            lo = min(lo, run_lo)
            hi = max(hi, run_hi)
        else:
            for j in range(start, stop):
                u = np.int32(bits[j])
                m = np.int32(u & np.int32(0x7FFF))
                fin = m < np.int32(HALF_INF_KEY)
                nonzero += np.int64(m != 0)
                nonfinite += np.int64(m >= np.int32(HALF_INF_KEY))
                key = np.int32(~m) if u >= np.int32(0x8000) else m
                lo = min(lo, key if fin else np.int32(0x7FFF))
                hi = max(hi, key if fin else np.int32(-0x8000))
                run[j - start] = np.int32(((u & np.int32(0x8000)) << np.int32(16))
                                          | (m << np.int32(13))) if fin else np.int32(0)
        acc = 0.0
        for j in range(stop - start):
            acc += np.float64(scaled[j])
        whole = np.int64(acc * 2.0**136)  # exact: the sum times 2^24, an integer below 2^53
        high += whole >> np.int64(32)
        low += whole & np.int64(_LOW)
    return lo, hi, nonzero, nonfinite, high, low


@njit(cache=True, nogil=True)
def float_stats(vals: np.ndarray, bits: np.ndarray, finite_only: bool):
    """One pass over a float32 plane.

    Parameters
    ----------
    vals : (H, W) float32 ndarray, C-contiguous
    bits : (H, W) int32 ndarray
        ``vals`` viewed as int32.
    finite_only : bool
        As :func:`half_stats`' (with :data:`FLOAT_INF_KEY`).

    Returns
    -------
    lo, hi : int
        The finite extremes as order keys (the bits of a non-negative float, those of a
        negative one with the magnitude's bits flipped; lo > hi when no texel is finite).
    nonzero, nonfinite : int
        Texels other than ±0 (infs and NaNs included), texels that are an inf or a NaN.
    total : float
        The finite texels' float64 sum in the module's order.
    """
    h, w = vals.shape
    fv = vals.ravel()
    fb = bits.ravel()
    col = np.zeros(w)
    mag = np.int32(0x7FFFFFFF)
    inf = np.int32(FLOAT_INF_KEY)
    lo = np.int32(0x7FFFFFFF)
    hi = np.int32(-0x80000000)
    nonzero = np.int64(0)
    nonfinite = np.int64(0)
    for i in range(h):
        base = i * w
        if finite_only:
            for j in range(w):
                b = fb[base + j]
                nonzero += np.int64((b & mag) != 0)
                key = np.int32(b ^ mag) if b < 0 else b
                lo = min(lo, key)
                hi = max(hi, key)
                col[j] += np.float64(fv[base + j])
            continue
        for j in range(w):
            b = fb[base + j]
            m = np.int32(b & mag)
            fin = m < inf
            nonzero += np.int64(m != 0)
            nonfinite += np.int64(m >= inf)
            key = np.int32(b ^ mag) if b < 0 else b
            lo = min(lo, key if fin else np.int32(0x7FFFFFFF))
            hi = max(hi, key if fin else np.int32(-0x80000000))
            col[j] += np.float64(fv[base + j]) if fin else 0.0
    total = 0.0
    for j in range(w):
        total += col[j]
    return lo, hi, nonzero, nonfinite, total


@njit(cache=True, nogil=True)
def wide_stats(vals: np.ndarray):
    """:func:`float_stats` of a float64 plane, with comparisons for the extremes
    (+inf, -inf when no texel is finite)."""
    h, w = vals.shape
    fv = vals.ravel()
    col = np.zeros(w)
    lo = np.inf
    hi = -np.inf
    nonzero = 0
    nonfinite = 0
    for i in range(h):
        base = i * w
        for j in range(w):
            x = fv[base + j]
            fin = x - x == 0.0
            nonzero += x != 0.0
            nonfinite += not fin
            if fin:
                lo = min(lo, x)
                hi = max(hi, x)
                col[j] += x
    total = 0.0
    for j in range(w):
        total += col[j]
    return lo, hi, nonzero, nonfinite, total


@njit(cache=True, nogil=True)
def uint_stats(a: np.ndarray):
    """One pass over a uint32 plane.

    Parameters
    ----------
    a : (N,) uint32 ndarray

    Returns
    -------
    lo, hi : int
        The extremes (lo > hi for an empty plane).
    nonzero : int
    sum_high, sum_low : int
        The exact sum is ``sum_high * 2^32 + sum_low``.
    """
    n = a.size
    lo = np.int64(_LOW)
    hi = np.int64(-1)
    nonzero = np.int64(0)
    high = np.int64(0)
    low = np.int64(0)
    for start in range(0, n, SEGMENT):
        acc = np.int64(0)
        for j in range(start, min(n, start + SEGMENT)):
            v = np.int64(a[j])
            nonzero += np.int64(v != 0)
            lo = min(lo, v)
            hi = max(hi, v)
            acc += v
        high += acc >> np.int64(32)
        low += acc & np.int64(_LOW)
    return lo, hi, nonzero, high, low


def warm() -> None:
    """Compile (or load from numba's cache) the kernels for every plane type a run writes or
    ``inspect`` reads (:mod:`crackbake.precompile`)."""
    for finite_only in (True, False):
        half_stats(np.zeros(6, np.uint16), finite_only)
        f = np.zeros((2, 3), np.float32)
        float_stats(f, f.view(np.int32), finite_only)
    wide_stats(np.zeros((2, 3), np.float64))
    uint_stats(np.zeros(6, np.uint32))
