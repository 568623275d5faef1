"""The max-heap of failing nodes (lazy: entries carry a version, stale ones are skipped)."""

from __future__ import annotations

from numba import njit


@njit(cache=True)
def heap_push(hk, hn, hv, cnt, key, node, ver):
    """Push (key, node, version); returns False when the heap is full."""
    i = cnt[0]
    if i >= hk.shape[0]:
        return False
    cnt[0] = i + 1
    while i > 0:
        p = (i - 1) // 2
        # Ties broken by the smaller node id so the order never depends on push history.
        if hk[p] > key or (hk[p] == key and hn[p] < node):
            break
        hk[i] = hk[p]
        hn[i] = hn[p]
        hv[i] = hv[p]
        i = p
    hk[i] = key
    hn[i] = node
    hv[i] = ver
    return True


@njit(cache=True)
def heap_pop(hk, hn, hv, cnt):
    """Pop the largest entry; returns (key, node, version)."""
    key, node, ver = hk[0], hn[0], hv[0]
    last = cnt[0] - 1
    cnt[0] = last
    if last > 0:
        lk, ln, lv = hk[last], hn[last], hv[last]
        i = 0
        while True:
            c = 2 * i + 1
            if c >= last:
                break
            if c + 1 < last and (hk[c + 1] > hk[c] or (hk[c + 1] == hk[c] and hn[c + 1] < hn[c])):
                c += 1
            if lk > hk[c] or (lk == hk[c] and ln < hn[c]):
                break
            hk[i] = hk[c]
            hn[i] = hn[c]
            hv[i] = hv[c]
            i = c
        hk[i] = lk
        hn[i] = ln
        hv[i] = lv
    return key, node, ver
