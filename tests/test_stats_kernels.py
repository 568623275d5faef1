"""crackbake.exchange.stats_kernels: each plane's statistics in one numba pass, through
:func:`crackbake.exchange.exrstats.plane_stats`, against numpy on the finite values and, for
the mean, the exact sum (``fractions``) or the documented summation order replayed in Python.
"""

from __future__ import annotations

import math
from fractions import Fraction

import numpy as np
import pytest

from crackbake.exchange.exrstats import plane_stats


def _reference(arr: np.ndarray) -> dict:
    """numpy's min, max and non-zero count of the finite values (widened), the exact mean."""
    wide = arr.astype(np.float64).ravel()
    good = wide[np.isfinite(wide)]
    return {
        "min": float(np.min(good)) if good.size else None,
        "max": float(np.max(good)) if good.size else None,
        "mean": float(sum(map(Fraction, good.tolist()), Fraction(0)) / good.size)
        if good.size else None,
        "nonzero": np.count_nonzero(wide) / wide.size if wide.size else 0.0,
        "nonfinite": int(wide.size - good.size),
    }  # fmt: skip


def _plane(dtype, shape, rng, case: str) -> np.ndarray:
    if dtype == np.uint32:
        a = rng.integers(0, 1 << 32, shape, dtype=np.uint64).astype(np.uint32)
        a[rng.random(shape) < 0.3] = 0
        if case == "extremes":
            a.ravel()[:2] = [0xFFFFFFFF, 0][: a.size]
        return a
    a = (rng.standard_normal(shape) * 300).astype(dtype)
    u = rng.random(shape)
    a[u < 0.2] = 0
    a[(u >= 0.2) & (u < 0.3)] = -0.0
    if case in ("specials", "all-nan"):
        a[(u >= 0.3) & (u < 0.35)] = np.nan
        a[(u >= 0.35) & (u < 0.38)] = np.inf
        a[(u >= 0.38) & (u < 0.41)] = -np.inf
    if case == "subnormal":
        tiny = np.finfo(dtype).smallest_subnormal
        a = (rng.integers(-1000, 1000, shape) * tiny).astype(dtype)
    if case == "extremes":
        big = np.finfo(dtype).max
        a.ravel()[:4] = [big, -big, np.finfo(dtype).smallest_subnormal, -0.0][: a.size]
    if case == "all-nan":
        a[...] = np.nan
        a.ravel()[:1] = np.inf
    return a


@pytest.mark.parametrize("dtype", [np.float16, np.float32, np.uint32, np.float64])
@pytest.mark.parametrize("case", ["plain", "specials", "subnormal", "extremes", "all-nan"])
@pytest.mark.parametrize("shape", [(37, 61), (1, 1), (3, 8), (0, 7), (5, 0)])
def test_kernel_matches_numpy_on_the_finite_values(dtype, case, shape):
    rng = np.random.default_rng(hash((np.dtype(dtype).str, case, shape)) % 2**32)
    arr = _plane(dtype, shape, rng, case)
    got, want = plane_stats(arr), _reference(arr)
    names = {np.float16: "half", np.float32: "float", np.uint32: "uint", np.float64: "float64"}
    assert got["type"] == names[dtype]
    for key in ("min", "max", "nonzero", "nonfinite"):
        assert got[key] == want[key], (key, got, want)
    if want["mean"] is None:
        assert got["mean"] is None
    elif dtype in (np.float32, np.float64):  # a float64 sum: its error scales with |values|
        scale = _reference(np.abs(arr.astype(np.float64)))["mean"]
        assert got["mean"] == pytest.approx(want["mean"], rel=1e-12, abs=1e-12 * scale)
    else:  # exact sum, one rounding
        assert got["mean"] == want["mean"]
    assert all(type(got[k]) is float for k in ("min", "max", "mean") if got[k] is not None)
    assert type(got["nonfinite"]) is int


def test_half_mean_is_exact_where_a_float64_sum_is_not():
    """A half plane's sum is exact (integers of 2^-24): 65504 beside 2^-24, whose float64
    running sum passes 2^29 and drops the 2^-24s after."""
    a = np.full((16, 4096), np.float16(65504))
    a[:, 1::2] = np.float16(2.0**-24)
    got = plane_stats(a)["mean"]
    half = a.size // 2
    exact = (Fraction(65504) * half + Fraction(half, 1 << 24)) / a.size
    assert got == float(exact) == 32752 + 2.0**-25
    running = 0.0
    for x in a.astype(np.float64).ravel().tolist():
        running += x
    assert running / a.size != got  # a running float64 sum loses some 2^-24


def test_float_mean_follows_the_documented_order():
    """Each column's float64 sum from the top row down, then the column sums from the left:
    replayed in Python floats, bit for bit (the order never depends on the machine)."""
    rng = np.random.default_rng(5)
    a = (rng.standard_normal((9, 29)) * 10.0 ** rng.integers(-8, 9, (9, 29))).astype(np.float32)
    a[2, 5] = np.nan
    a[4, 27] = -np.inf
    cols, finite = [0.0] * a.shape[1], 0
    for row in a.astype(np.float64).tolist():
        for j, x in enumerate(row):
            if math.isfinite(x):
                cols[j] += x
                finite += 1
    total = 0.0
    for c in cols:
        total += c
    assert plane_stats(a)["mean"] == total / finite


@pytest.mark.parametrize("dtype", [np.float16, np.uint32])
def test_long_rows_do_not_overflow_the_exact_sums(dtype):
    """Rows of the largest values, longer than the kernels' runs and than 2^20 texels."""
    big = np.finfo(np.float16).max if dtype == np.float16 else 0xFFFFFFFF
    a = np.full((2, (1 << 20) + 3), big, dtype)
    a[1, -1] = 0
    got = plane_stats(a)
    assert got["mean"] == float(Fraction(int(big)) * (a.size - 1) / a.size)
    assert (got["min"], got["max"]) == (0.0, float(big))


def test_other_layouts_give_the_same_figures():
    """A non-contiguous, big-endian or 1-D view gives its contiguous copy's statistics."""
    rng = np.random.default_rng(8)
    a = (rng.standard_normal((20, 30)) * 5).astype(np.float32)
    want = plane_stats(np.ascontiguousarray(a[:, ::2]))
    assert plane_stats(a[:, ::2]) == want
    swapped = plane_stats(a[:, ::2].astype(">f4"))
    assert swapped.pop("type") == ">f4"  # named as numpy names it, as before
    assert swapped == {k: v for k, v in want.items() if k != "type"}
    flat = a.ravel()
    assert plane_stats(flat) == plane_stats(flat.reshape(1, -1))


@pytest.mark.parametrize("dtype", [np.float16, np.float32])
@pytest.mark.parametrize("special", ["+inf", "-inf", "+nan", "-nan"])
def test_a_single_inf_or_nan_of_either_sign_is_found_and_skipped(dtype, special):
    """The first pass takes every texel as finite and looks for an inf or a NaN in its
    extreme keys: one texel of each kind and sign, anywhere, must send the plane through the
    finite test."""
    rng = np.random.default_rng(21)
    a = rng.uniform(-2, 3, (13, 17)).astype(dtype)
    value = {"+inf": np.inf, "-inf": -np.inf, "+nan": np.nan, "-nan": -np.nan}[special]
    for at in [(0, 0), (6, 9), (12, 16)]:
        b = a.copy()
        b[at] = value
        if special == "-nan":  # numpy's -nan keeps its sign bit; make sure of it
            b.view(np.uint16 if dtype == np.float16 else np.uint32)[at] |= (
                0x8000 if dtype == np.float16 else 0x80000000)  # fmt: skip
        got, want = plane_stats(b), _reference(b)
        assert got["nonfinite"] == 1
        for key in ("min", "max", "nonzero"):
            assert got[key] == want[key], (key, got, want)
        assert got["mean"] == pytest.approx(want["mean"], rel=1e-12)
