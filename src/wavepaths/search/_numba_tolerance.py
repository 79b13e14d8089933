"""The numba twins of the tolerance of coverage maps (``TraceOptions.tolerance_db``): the
diffracted candidates' amplitude bounds (:func:`wavepaths.search.diffraction._diffraction_amplitude_bound`)
and the choice of the candidates dropped (:func:`wavepaths.coverage.tolerance.tolerance_drop_numpy`),
imported only when numba is installed; the numpy functions named in each comment are the
references."""

import math

import numba
import numpy as np

from ._numba import _counting_sort


@numba.njit(cache=True, nogil=True)
def amplitude_bounds(phi, phi_prime, n, te, de, tr, dr, t, k, floor, utd_floor):
    # diffraction._diffraction_amplitude_bound with em.utd.utd_magnitude_bound (numpy
    # references), candidate by candidate: (k,) 1.01 |D|_max / sqrt(s' s (s' + s)), inf
    # where the reference's is not finite (a NaN anywhere in it gives inf there too)
    m = phi.shape[0]
    out = np.empty(m)
    two_pi = 2.0 * math.pi
    root_k = math.sqrt(two_pi * k)
    for i in range(m):
        a_t, b_t = te[i] - t[i], tr[i] - t[i]
        s_in = math.sqrt(a_t * a_t + de[i] * de[i])
        s_out = math.sqrt(b_t * b_t + dr[i] * dr[i])
        q = de[i] / s_in if s_in != 0.0 else math.nan  # s_in = 0: de = 0 too, the reference's 0 / 0
        if q != q:
            out[i] = math.inf
            continue
        sin_b = q if q > floor else floor
        L = s_in * s_out / (s_in + s_out) * sin_b ** 2  # s_in > 0 here
        nn = n[i]
        sb = abs(sin_b)
        sb = sb if sb > utd_floor else utd_floor  # utd_magnitude_bound's sin_beta_0_floor
        cap = nn * math.sqrt(two_pi * k * L) if L >= 0.0 else math.nan
        two_pi_n = two_pi * nn
        bm = phi[i] - phi_prime[i]
        bp = phi[i] + phi_prime[i]
        total = 0.0
        for e in range(4):
            b = bm if e < 2 else bp
            if e % 2 == 0:  # em.utd_terms._epsilons: eps_plus, eps_minus (np.round: half to even)
                eps = (math.pi + b) - two_pi_n * np.rint((b + math.pi) / two_pi_n)
            else:
                eps = (math.pi - b) + two_pi_n * np.rint((b - math.pi) / two_pi_n)
            # |cot(x)|, x = eps / 2n (the reference's |cos x| / |sin x|, one call)
            tx = abs(math.tan(eps / (2.0 * nn)))
            c = 1.0 / tx if tx != 0.0 else math.inf
            total += c if c < cap else cap  # np.minimum: a NaN cap gives NaN
        den = s_in * s_out * (s_in + s_out)
        amp = 1.01 * (total / (2.0 * nn * root_k * sb)) / math.sqrt(den) if den > 0.0 else math.inf
        out[i] = amp if math.isfinite(amp) else math.inf
    return out


@numba.njit(cache=True, nogil=True)
def tolerance_drop(pair, bound, go_power, eps, n_pairs):
    # coverage.tolerance.tolerance_drop_numpy (the reference): per (transmitter, cell) pair,
    # its candidates by bound (ties in their order), as np.lexsort((bound, pair)); one
    # running sum per pair, started at 0 and added in that order as the reference's
    # (infinite bounds counted as 0, never dropped), each candidate dropped while its pair's
    # sum stays <= eps * go_power[pair]. The sum is the pair's own: a sum carried over the
    # pairs, less its value at the pair's start, lost bounds below ~1e-16 of the earlier
    # pairs' total (dropped whatever their size against their own cell's power).
    # The pairs are grouped by a counting sort. Returns (k,) bool, True: dropped
    k = pair.shape[0]
    start, members = _counting_sort(pair, n_pairs)
    drop = np.zeros(k, np.bool_)
    for p in range(n_pairs):
        lo, hi = start[p], start[p + 1]
        if hi == lo:
            continue
        idx = members[lo:hi]
        b = np.empty(hi - lo)
        for j in range(hi - lo):
            b[j] = bound[idx[j]]
        order = np.argsort(b, kind="mergesort")
        limit = eps * go_power[p]
        cum = 0.0  # this pair's own sum
        for j in range(hi - lo):
            v = b[order[j]]
            finite = math.isfinite(v)
            cum += v if finite else 0.0
            drop[idx[order[j]]] = finite and cum <= limit
    return drop
