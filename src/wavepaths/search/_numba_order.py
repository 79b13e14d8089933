"""The numba ordering of paths: a stable counting sort on a bounded integer key
(:func:`_counting_sort`, also used by :mod:`wavepaths.search._numba_tolerance`), and
``np.lexsort((lengths, key))`` built on it (:func:`key_length_order`) for
:func:`wavepaths.search.paths.path_order`, whose order puts the repeated paths next to each
other for their deduplication. Imported only when numba is installed."""

import numba
import numpy as np


@numba.njit(cache=True, nogil=True, inline="always")
def _counting_sort(key, n_keys):
    """A stable counting sort of ``key`` (``0 <= key < n_keys``): ``(start, order)``, the rows of
    key ``b`` being ``order[start[b]:start[b + 1]]`` in their original order."""
    n = key.size
    start = np.zeros(n_keys + 1, np.int64)
    for i in range(n):
        start[key[i] + 1] += 1
    for b in range(n_keys):
        start[b + 1] += start[b]
    fill = start[:-1].copy()
    order = np.empty(n, np.int64)
    for i in range(n):
        b = key[i]
        order[fill[b]] = i
        fill[b] += 1
    return start, order


@numba.njit(cache=True, nogil=True)
def key_length_order(key, lengths, n_keys):
    """``np.lexsort((lengths, key))`` for ``0 <= key < n_keys``: a stable counting sort on
    ``key``, then each key's rows by length (insertion sort, stable; numba's merge sort,
    stable too, for a key holding more than 32 rows). Returns ``(order, tie)``: ``tie`` is True when two
    rows share both key and length (the caller then sorts on the whole key).
    Lengths must not be NaN (the caller checks)."""
    start, order = _counting_sort(key, n_keys)
    tie = False
    for b in range(n_keys):
        lo, hi = start[b], start[b + 1]
        if hi - lo > 32:
            part = order[lo:hi].copy()
            sub = np.argsort(lengths[part], kind="mergesort")
            for j in range(hi - lo):
                order[lo + j] = part[sub[j]]
        else:
            for j in range(lo + 1, hi):
                v = order[j]
                x = lengths[v]
                m = j - 1
                while m >= lo and lengths[order[m]] > x:
                    order[m + 1] = order[m]
                    m -= 1
                order[m + 1] = v
        for j in range(lo + 1, hi):
            if lengths[order[j]] == lengths[order[j - 1]]:
                tie = True
    return order, tie
