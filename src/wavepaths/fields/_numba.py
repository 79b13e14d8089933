"""The numba kernels behind :mod:`wavepaths.fields.compiled` (imported only when numba is installed).

Each function is the compiled twin of a numpy reference named in its docstring, with the
same formulas term for term (the references' docstrings give them and their sources).
The Faddeeva function is scipy's own (``scipy.special.cython_special.erfcx``), called
through its C entry point, whose address is passed in at run time (``erfcx_addr``) so
that the cached machine code never holds a stale address.
"""

import math

import llvmlite.ir as ir
import numba
import numpy as np
from numba import types
from numba.extending import intrinsic

KIND_DIELECTRIC = 0
KIND_PEC = 1
KIND_ABSORBER = 2

_TINY = 1e-200  # wavepaths.em.fresnel._TINY
_HUGE = 1e100  # wavepaths.em.fresnel._HUGE: a perfect conductor above this |eta|
_E_PI4 = complex(math.cos(0.25 * math.pi), math.sin(0.25 * math.pi))
_E_MPI4 = complex(math.cos(0.25 * math.pi), -math.sin(0.25 * math.pi))
_SQRT_PI = math.sqrt(math.pi)
F_SERIES_X = 100.0  # wavepaths.em.utd_terms._F_SERIES_X


@intrinsic
def _call_erfcx(typingctx, addr, re, im):
    """Call ``double complex erfcx(double complex, int)`` at address ``addr``.

    A C99 ``double complex`` (or Cython's two-double struct) is passed and returned in two
    floating-point registers on x86-64 and aarch64, as two doubles are: the function is
    declared with two double arguments and a two-double struct result.
    :func:`wavepaths.fields.compiled.available` checks the result against scipy once.
    """
    sig = types.UniTuple(types.float64, 2)(types.uint64, types.float64, types.float64)

    def codegen(context, builder, signature, args):
        d = ir.DoubleType()
        fnty = ir.FunctionType(ir.LiteralStructType([d, d]), [d, d, ir.IntType(32)])
        ptr = builder.inttoptr(args[0], fnty.as_pointer())
        res = builder.call(ptr, [args[1], args[2], ir.Constant(ir.IntType(32), 0)])
        return context.make_tuple(builder, signature.return_type,
                                  [builder.extract_value(res, 0), builder.extract_value(res, 1)])

    return sig, codegen


@numba.njit(cache=True, nogil=True)
def erfcx(addr, z):
    """scipy.special.erfcx(z) for complex ``z``."""
    a, b = _call_erfcx(addr, z.real, z.imag)
    return complex(a, b)


@numba.njit(cache=True, nogil=True)
def erfcx_array(addr, z):
    """:func:`erfcx` over an array (for the self-check against scipy)."""
    out = np.empty(z.shape, np.complex128)
    for i in range(z.size):
        out[i] = erfcx(addr, z[i])
    return out


@numba.njit(cache=True, nogil=True)
def _g(addr, x):
    # wavepaths.em.utd_terms._g: G(x) = F(x)/sqrt(x), from x = 100 on by F's asymptotic series
    if x >= F_SERIES_X:
        return f_series(x) / math.sqrt(x)
    return _E_PI4 * _SQRT_PI * erfcx(addr, _E_PI4 * math.sqrt(x))


@numba.njit(cache=True, nogil=True)
def f_series(x):
    """F(x) for x >= 100 by its asymptotic series: :func:`wavepaths.em.utd_terms._f_series`, the
    same polynomial."""
    u = 0.5 / x
    v = u * u
    re = 1.0 + v * (-3.0 + v * (105.0 + v * (-10395.0 + v * (2027025.0 + v * -654729075.0))))
    im = u * (1.0 + v * (-15.0 + v * (945.0 + v * (-135135.0 + v * (34459425.0 + v * -13749310575.0)))))
    return complex(re, im)


@numba.njit(cache=True, nogil=True, inline="always")
def _cot_f(addr, eps, n, kl, root_2kl):
    # wavepaths.em.utd_terms._cot_f: cot(eps/2n) F(2 kL sin^2(eps/2)), 0 at eps = 0. With h = eps/2,
    # g = h/n and F(x) = sqrt(x) G(x), sqrt(x) = sqrt(2kL) |sin h|: the term is
    # sign(eps) sqrt(2kL) cos g (sin h / sin g) G(x), where sin h / sin g > 0 (|h| <= pi) is
    # the reference's n sinc(eps/2pi) / sinc(eps/2pi n), and n where sin g underflows
    if eps == 0.0:
        return 0j
    h = 0.5 * eps
    g = h / n
    s = math.sin(h)
    sg = math.sin(g)
    ratio = s / sg if sg != 0.0 else n
    x = 2.0 * kl * s * s
    sgn = 1.0 if eps > 0.0 else -1.0
    return sgn * root_2kl * math.cos(g) * ratio * _g(addr, x)


@numba.njit(cache=True, nogil=True)
def luebbers(addr, phi, phi_prime, beta_0, n, k, L, r0_s, r0_h, rn_s, rn_h, floor):
    """(D_s, D_h) of :func:`wavepaths.em.utd.luebbers_coefficients` at one point."""
    base, d4, d3 = luebbers_terms(addr, phi, phi_prime, beta_0, n, k, L, floor)
    return base + r0_s * d4 + rn_s * d3, base + r0_h * d4 + rn_h * d3


@numba.njit(cache=True, nogil=True)
def luebbers_terms(addr, phi, phi_prime, beta_0, n, k, L, floor):
    """``(D1 + D2, D4, D3)`` of :func:`wavepaths.em.utd.luebbers_coefficients` (the four terms
    with their prefactor) at one point."""
    sb = max(abs(math.sin(beta_0)), floor)
    pref = -_E_MPI4 / (2.0 * n * math.sqrt(2.0 * math.pi * k) * sb)
    two_pi_n = 2.0 * math.pi * n
    bm = phi - phi_prime
    bp = phi + phi_prime
    kl = k * L
    root_2kl = math.sqrt(2.0 * kl)
    # wavepaths.em.utd_terms._epsilons (np.round is round-half-even, as np.rint)
    t1 = _cot_f(addr, (math.pi + bm) - two_pi_n * np.rint((bm + math.pi) / two_pi_n), n, kl, root_2kl)
    t2 = _cot_f(addr, (math.pi - bm) + two_pi_n * np.rint((bm - math.pi) / two_pi_n), n, kl, root_2kl)
    t3 = _cot_f(addr, (math.pi + bp) - two_pi_n * np.rint((bp + math.pi) / two_pi_n), n, kl, root_2kl)
    t4 = _cot_f(addr, (math.pi - bp) + two_pi_n * np.rint((bp - math.pi) / two_pi_n), n, kl, root_2kl)
    return pref * (t1 + t2), pref * t4, pref * t3


@numba.njit(cache=True, nogil=True, inline="always")
def _csqrt(a, b):
    # the principal square root of a + jb (numpy's branch: Re >= 0, Im with the sign of b,
    # signed zeros included), as (re, im)
    if a == 0.0 and b == 0.0:
        return 0.0, b
    m = math.sqrt(a * a + b * b)  # |a + jb|
    if not 1e-150 < m < 1e150:  # the squares under- or overflow (a near-vacuum or a huge eta): libm's careful form
        m = math.hypot(a, b)
    if a >= 0.0:
        t = math.sqrt(0.5 * (m + a))
        return t, 0.5 * b / t
    t = math.sqrt(0.5 * (m - a))
    return 0.5 * abs(b) / t, math.copysign(t, b)


@numba.njit(cache=True, nogil=True, inline="always")
def _inv_sq(t):
    # 1 / t^2 for |t|^2 >= _TINY: (conj(t) / |t|^2)^2
    a = t.real * t.real + t.imag * t.imag
    u = complex(t.real / a, -t.imag / a)
    return u * u


@numba.njit(cache=True, nogil=True)
def fresnel(kind, eta, thickness_over_lambda, slab, c):
    """(r_te, r_tm) of :func:`wavepaths.em.fresnel.reflection_coefficients` at one angle.

    ``kind``: ``KIND_DIELECTRIC`` (``eta`` used), ``KIND_PEC`` or ``KIND_ABSORBER``;
    ``slab``: the single-layer slab of thickness ``thickness_over_lambda`` wavelengths, else
    the half-space. The reference's formulas (P.2040 eqs. 37, 43-44 in the rationalised
    form of :func:`wavepaths.em.fresnel._half_space_parts`), with its transcendental
    functions shared: one sine, cosine, exponential and expm1 for the slab's two phase
    terms, and ``|den|`` of a square as the squared modulus of its root. Equal to the
    reference to rounding (about 1e-15 relative).
    """
    if kind == KIND_PEC:
        return -1.0 + 0j, 1.0 + 0j
    if kind == KIND_ABSORBER:
        return 0j, 0j
    c = min(abs(c), 1.0)
    huge = eta.real * eta.real + eta.imag * eta.imag > _HUGE * _HUGE  # |eta| > _HUGE (inf past 1e154): a perfect conductor
    if huge:
        eta = 2.0 + 0j  # a stand-in that keeps the squares below finite; overridden after them
    # _half_space_parts, with root = sqrt((eta - 1) + c^2), den = (c + root)^2, (eta c + root)^2
    w = (eta - 1.0) + c * c
    # the branch with Im <= 0 (wavepaths.em.fresnel._root): a zero imaginary part taken as -0
    rr, ri = _csqrt(w.real, w.imag if w.imag != 0.0 else -0.0)
    root = complex(rr, ri)
    t_te = c + root
    t_tm = eta * c + root
    a_te = t_te.real * t_te.real + t_te.imag * t_te.imag  # |den_te|
    a_tm = t_tm.real * t_tm.real + t_tm.imag * t_tm.imag
    if eta == 1.0 or a_te < _TINY or a_tm < _TINY:
        r_te, r_tm, om_te, om_tm = 0j, 0j, 1.0 + 0j, 1.0 + 0j
    else:
        i_te = _inv_sq(t_te)
        i_tm = _inv_sq(t_tm)
        r_te = (1.0 - eta) * i_te
        r_tm = (eta - 1.0) * ((eta + 1.0) * c * c - 1.0) * i_tm
        om_te = 4.0 * c * root * i_te
        om_tm = 4.0 * eta * c * root * i_tm
    if huge:  # the slab's R is then r whatever its phase (1 - r^2 = 0): the stand-in's q is harmless
        r_te, r_tm, om_te, om_tm = -1.0 + 0j, 1.0 + 0j, 0j, 0j
    if not slab:
        return r_te, r_tm
    if thickness_over_lambda == 0.0:
        return 0j, 0j  # no slab (wavepaths.em.fresnel._slab)
    # _slab, eqs. (43)-(44): q = 2 pi d/lambda root, e1 = e^{-jq}, e2 = e1^2 and
    # 1 - e2 = -expm1(-2jq) = 2 sin^2(q') - expm1(2q'') cos(2q') + 2j e^{2q''} sin(q') cos(q')
    # (q = q' + jq''; numpy's complex expm1 with the half-angle sine)
    q = (2.0 * math.pi * thickness_over_lambda) * root
    sq = math.sin(q.real)
    cq = math.cos(q.real)
    ex = math.exp(q.imag)
    e1 = complex(ex * cq, -ex * sq)
    e2 = e1 * e1
    one_minus_e2 = complex(2.0 * sq * sq - math.expm1(2.0 * q.imag) * ((cq - sq) * (cq + sq)),
                           2.0 * (ex * ex) * (sq * cq))
    return _slab_r(r_te, om_te, one_minus_e2, e2), _slab_r(r_tm, om_tm, one_minus_e2, e2)


@numba.njit(cache=True, nogil=True, inline="always")
def _slab_r(r, om, one_minus_e2, e2):
    # eq. (43a): r (1 - e2) / (1 - r^2 e2) with 1 - r^2 e2 = (1 - e2) + (1 - r^2) e2; r itself
    # where |den| < _TINY (the reference's threshold). By the conjugate where |num| and |den|
    # both exceed 1e-145 (their products stay normal); else numba's complex division
    den = one_minus_e2 + om * e2
    num = r * one_minus_e2
    a = den.real * den.real + den.imag * den.imag
    if a > 1e-290 and num.real * num.real + num.imag * num.imag > 1e-290:
        return complex((num.real * den.real + num.imag * den.imag) / a, (num.imag * den.real - num.real * den.imag) / a)
    return r if abs(den) < _TINY else num / den


@numba.njit(cache=True, nogil=True, inline="always")
def _perp_unit(a0, a1, a2, b0, b1, b2, f0, f1, f2):
    # wavepaths.fields.chain._perp_unit: unit(a x b), or the fallback where a and b are parallel
    c0 = a1 * b2 - a2 * b1
    c1 = a2 * b0 - a0 * b2
    c2 = a0 * b1 - a1 * b0
    nn = math.sqrt(c0 * c0 + c1 * c1 + c2 * c2)
    if nn > 1e-12:
        return c0 / nn, c1 / nn, c2 / nn
    return f0, f1, f2


@numba.njit(cache=True, nogil=True, inline="always")
def _edge_reflection(r_te, r_tm, ki0, ki1, ki2, ko0, ko1, ko2, n0, n1, n2, bi0, bi1, bi2, fi0, fi1, fi2, bo0, bo1, bo2,
                     fo0, fo1, fo2):
    # wavepaths.em.wedge_faces.edge_fixed_reflection at one point, with the edge-fixed bases (b0', phi')
    # of k_in and (b0, phi) of k_out given: G = -B_out^T R B_in, its four entries (rows b0, phi;
    # columns b0', phi'), the same expressions. The TE direction s = unit(k_in x n), or where
    # k_in runs along n, the reflection kernel's fallback unit(n x z) (or x)
    c0, c1, c2 = ki1 * n2 - ki2 * n1, ki2 * n0 - ki0 * n2, ki0 * n1 - ki1 * n0
    m = math.sqrt(c0 * c0 + c1 * c1 + c2 * c2)
    if m > 1e-12:
        s0, s1, s2 = c0 / m, c1 / m, c2 / m
    else:
        s0, s1, s2 = _perp_unit(n0, n1, n2, 0.0, 0.0, 1.0, 1.0, 0.0, 0.0)
    pi0, pi1, pi2 = s1 * ki2 - s2 * ki1, s2 * ki0 - s0 * ki2, s0 * ki1 - s1 * ki0
    pr0, pr1, pr2 = s1 * ko2 - s2 * ko1, s2 * ko0 - s0 * ko2, s0 * ko1 - s1 * ko0
    # u.s, u.p_r for the output vectors u; s.v, p_i.v for the input vectors v
    bs, bp = (bo0 * s0 + bo1 * s1) + bo2 * s2, (bo0 * pr0 + bo1 * pr1) + bo2 * pr2
    fs, fp = (fo0 * s0 + fo1 * s1) + fo2 * s2, (fo0 * pr0 + fo1 * pr1) + fo2 * pr2
    sb, pb = (s0 * bi0 + s1 * bi1) + s2 * bi2, (pi0 * bi0 + pi1 * bi1) + pi2 * bi2
    sf, pf = (s0 * fi0 + s1 * fi1) + s2 * fi2, (pi0 * fi0 + pi1 * fi1) + pi2 * fi2
    return (-(r_te * (bs * sb) + r_tm * (bp * pb)), -(r_te * (bs * sf) + r_tm * (bp * pf)),
            -(r_te * (fs * sb) + r_tm * (fp * pb)), -(r_te * (fs * sf) + r_tm * (fp * pf)))


@numba.njit(cache=True, nogil=True)
def reflect(E, k_in, k_out, normal, material, kinds, etas, thick, slab):
    """:func:`wavepaths.fields.chain._apply_reflection`, in place on ``E`` (k, P, 3).

    ``normal`` (k, 3) the mirror's unit normal, ``material`` (k,) its material index into
    ``kinds``, ``etas``, ``thick`` (thickness in wavelengths).
    """
    for r in range(E.shape[0]):
        _reflect_core(E, r, k_in[r, 0], k_in[r, 1], k_in[r, 2], k_out[r, 0], k_out[r, 1], k_out[r, 2],
                      normal[r, 0], normal[r, 1], normal[r, 2], material[r], kinds, etas, thick, slab)


@numba.njit(cache=True, nogil=True, inline="always")
def _reflect_coeffs(ki0, ki1, ki2, ko0, ko1, ko2, n0, n1, n2, kind, eta, thk, slab):
    # the Fresnel coefficients and the TE, incident TM and reflected TM unit vectors of a reflection
    # (scalars only: an array argument of an inlined helper is reference-counted at every call)
    cos_t = abs(ki0 * n0 + ki1 * n1 + ki2 * n2)
    f0, f1, f2 = _perp_unit(n0, n1, n2, 0.0, 0.0, 1.0, 1.0, 0.0, 0.0)
    s0, s1, s2 = _perp_unit(ki0, ki1, ki2, n0, n1, n2, f0, f1, f2)
    pi0, pi1, pi2 = s1 * ki2 - s2 * ki1, s2 * ki0 - s0 * ki2, s0 * ki1 - s1 * ki0
    pr0, pr1, pr2 = s1 * ko2 - s2 * ko1, s2 * ko0 - s0 * ko2, s0 * ko1 - s1 * ko0
    r_te, r_tm = fresnel(kind, eta, thk, slab, cos_t)
    return r_te, r_tm, s0, s1, s2, pi0, pi1, pi2, pr0, pr1, pr2


@numba.njit(cache=True, nogil=True, inline="always")
def _reflect_core(E, r, ki0, ki1, ki2, ko0, ko1, ko2, n0, n1, n2, m, kinds, etas, thick, slab):
    """One row of :func:`reflect`: row ``r`` of ``E`` reflected on a face of normal ``n`` and material ``m``."""
    r_te, r_tm, s0, s1, s2, pi0, pi1, pi2, pr0, pr1, pr2 = _reflect_coeffs(ki0, ki1, ki2, ko0, ko1, ko2, n0, n1, n2,
                                                                           kinds[m], etas[m], thick[m], slab)
    for p in range(E.shape[1]):
        e0, e1, e2 = E[r, p, 0], E[r, p, 1], E[r, p, 2]
        es = r_te * (e0 * s0 + e1 * s1 + e2 * s2)
        ep = r_tm * (e0 * pi0 + e1 * pi1 + e2 * pi2)
        E[r, p, 0] = es * s0 + ep * pr0
        E[r, p, 1] = es * s1 + ep * pr1
        E[r, p, 2] = es * s2 + ep * pr2


@numba.njit(cache=True, nogil=True, inline="always")
def _diffract_row(addr, r, E, e, s_in, s_out, x_fallback, y_face, phi, phi_prime, beta_0, n, L, k, floor, mat_0,
                  mat_n, kinds, etas, thick, slab):
    _diffract_core(addr, E, r, e[r, 0], e[r, 1], e[r, 2], s_in[r, 0], s_in[r, 1], s_in[r, 2], s_out[r, 0],
                   s_out[r, 1], s_out[r, 2], x_fallback[r, 0], x_fallback[r, 1], x_fallback[r, 2],
                   (y_face[r, 0], y_face[r, 1], y_face[r, 2]), phi[r], phi_prime[r], beta_0[r], n[r], L[r], k, floor,
                   mat_0[r], mat_n[r], kinds, etas, thick, slab)


@numba.njit(cache=True, nogil=True, inline="always")
def _diffract_core(addr, E, r, e0, e1, e2, a0, a1, a2, o0, o1, o2, f0, f1, f2, y, phi, phi_prime, b0, nr, L, k, floor,
                   m0, mn, kinds, etas, thick, slab):
    """One row of :func:`diffract`: edge ``e``, directions ``s_in`` = ``a``, ``s_out`` = ``o``,
    fallback ``f`` (the 0-face direction), ``y`` the n-face direction (a 3-tuple), the UTD
    angles, ``L``, the faces' materials. The Jones matrix is
    :func:`wavepaths.em.utd.diffraction_jones_matrices`' with the faces' reflections of
    :func:`wavepaths.em.wedge_faces.wedge_reflection_matrices` (:func:`_edge_reflection`)."""
    (j00, j01, j10, j11, bi0, bi1, bi2, pi0, pi1, pi2, bo0, bo1, bo2, po0, po1,
     po2) = _diffract_coeffs(addr, e0, e1, e2, a0, a1, a2, o0, o1, o2, f0, f1, f2, y, phi, phi_prime, b0, nr, L, k,
                             floor, kinds[m0], etas[m0], thick[m0], kinds[mn], etas[mn], thick[mn], slab)
    for p in range(E.shape[1]):
        x0, x1, x2 = E[r, p, 0], E[r, p, 1], E[r, p, 2]
        cb = x0 * bi0 + x1 * bi1 + x2 * bi2
        cp = x0 * pi0 + x1 * pi1 + x2 * pi2
        ob = j00 * cb + j01 * cp
        op = j10 * cb + j11 * cp
        E[r, p, 0] = ob * bo0 + op * po0
        E[r, p, 1] = ob * bo1 + op * po1
        E[r, p, 2] = ob * bo2 + op * po2


@numba.njit(cache=True, nogil=True, inline="always")
def _diffract_coeffs(addr, e0, e1, e2, a0, a1, a2, o0, o1, o2, f0, f1, f2, y, phi, phi_prime, b0, nr, L, k, floor,
                     kind0, eta0, thk0, kindn, etan, thkn, slab):
    # _diffract_core's Jones matrix J and its bases (b0', phi') of s_in, (b0, phi) of s_out, from
    # scalars only (the faces' materials as their kind, eta and thickness)
    sb = abs(math.sin(b0))
    r0_s, r0_h = fresnel(kind0, eta0, thk0, slab, sb * abs(math.sin(phi_prime)))
    rn_s, rn_h = fresnel(kindn, etan, thkn, slab, sb * abs(math.sin(nr * math.pi - phi)))
    base, d4, d3 = luebbers_terms(addr, phi, phi_prime, b0, nr, k, L, floor)
    pi0, pi1, pi2 = _perp_unit(a0, a1, a2, e0, e1, e2, f0, f1, f2)
    bi0, bi1, bi2 = a1 * pi2 - a2 * pi1, a2 * pi0 - a0 * pi2, a0 * pi1 - a1 * pi0
    po0, po1, po2 = _perp_unit(e0, e1, e2, o0, o1, o2, f0, f1, f2)
    bo0, bo1, bo2 = o1 * po2 - o2 * po1, o2 * po0 - o0 * po2, o0 * po1 - o1 * po0
    # the faces' normals (chain._apply_diffraction: _perp_unit(e, face direction, 0-face direction))
    n00, n01, n02 = _perp_unit(e0, e1, e2, f0, f1, f2, f0, f1, f2)
    nn0, nn1, nn2 = _perp_unit(e0, e1, e2, y[0], y[1], y[2], f0, f1, f2)
    # G0: the 0-face reflecting s_in into its mirror m (input basis: s_in's own)
    c = (a0 * n00 + a1 * n01) + a2 * n02
    m0_, m1_, m2_ = a0 - 2.0 * c * n00, a1 - 2.0 * c * n01, a2 - 2.0 * c * n02
    q0, q1, q2 = _perp_unit(e0, e1, e2, m0_, m1_, m2_, f0, f1, f2)
    g00, g01, g10, g11 = _edge_reflection(r0_s, r0_h, a0, a1, a2, m0_, m1_, m2_, n00, n01, n02, bi0, bi1, bi2, pi0,
                                          pi1, pi2, m1_ * q2 - m2_ * q1, m2_ * q0 - m0_ * q2, m0_ * q1 - m1_ * q0, q0,
                                          q1, q2)
    # Gn: the n-face reflecting the mirror m of s_out into s_out (output basis: s_out's own)
    c = (o0 * nn0 + o1 * nn1) + o2 * nn2
    m0_, m1_, m2_ = o0 - 2.0 * c * nn0, o1 - 2.0 * c * nn1, o2 - 2.0 * c * nn2
    q0, q1, q2 = _perp_unit(m0_, m1_, m2_, e0, e1, e2, f0, f1, f2)
    h00, h01, h10, h11 = _edge_reflection(rn_s, rn_h, m0_, m1_, m2_, o0, o1, o2, nn0, nn1, nn2, m1_ * q2 - m2_ * q1,
                                          m2_ * q0 - m0_ * q2, m0_ * q1 - m1_ * q0, q0, q1, q2, bo0, bo1, bo2, po0,
                                          po1, po2)
    # J = -[(D1 + D2) I + D4 G0 + D3 Gn]
    j00 = -((d4 * g00 + d3 * h00) + base)
    j01 = -(d4 * g01 + d3 * h01)
    j10 = -(d4 * g10 + d3 * h10)
    j11 = -((d4 * g11 + d3 * h11) + base)
    return j00, j01, j10, j11, bi0, bi1, bi2, pi0, pi1, pi2, bo0, bo1, bo2, po0, po1, po2


@numba.njit(cache=True, nogil=True)
def diffract(addr, E, e, s_in, s_out, x_fallback, y_face, phi, phi_prime, beta_0, n, L, k, floor, mat_0, mat_n,
             kinds, etas, thick, slab):
    """:func:`wavepaths.fields.chain._apply_diffraction` after the wedge geometry, model
    ``"utd"`` (Luebbers' face coefficients at their angles,
    :func:`wavepaths.em.wedge_faces.luebbers_face_coefficients`, as the faces' reflections in the
    edge-fixed bases), in place on ``E`` (k, P, 3); ``x_fallback`` and ``y_face`` (k, 3) the
    0-face and n-face directions.
    """
    for r in range(E.shape[0]):
        _diffract_row(addr, r, E, e, s_in, s_out, x_fallback, y_face, phi, phi_prime, beta_0, n, L, k, floor, mat_0,
                      mat_n, kinds, etas, thick, slab)


@numba.njit(cache=True, nogil=True, parallel=True)
def diffract_parallel(addr, E, e, s_in, s_out, x_fallback, y_face, phi, phi_prime, beta_0, n, L, k, floor, mat_0,
                      mat_n, kinds, etas, thick, slab):
    """:func:`diffract` with the rows on numba's threads (each row is independent)."""
    for r in numba.prange(E.shape[0]):
        _diffract_row(addr, r, E, e, s_in, s_out, x_fallback, y_face, phi, phi_prime, beta_0, n, L, k, floor, mat_0,
                      mat_n, kinds, etas, thick, slab)


@numba.njit(cache=True, nogil=True)
def _angle(v0, v1, v2, x0, x1, x2, y0, y1, y2):
    # wavepaths.fields.chain.wedge_geometry's angle(): mod(arctan2(v.y, v.x), 2 pi)
    a = math.atan2(v0 * y0 + v1 * y1 + v2 * y2, v0 * x0 + v1 * x1 + v2 * x2)
    return a + 2.0 * math.pi if a < 0.0 else a  # Python's a % 2 pi for -2 pi < a < 0, the same addition


@numba.njit(cache=True, nogil=True)
def wedge_geometry(vertices, rows, j, dihedron, face_0, face_n, direction, face_direction):
    """The angles and directions of :func:`wavepaths.fields.chain.wedge_geometry` (its
    numpy reference), for the diffraction at interaction ``j`` of paths ``rows``.

    Returns ``e``, ``s_in``, ``s_out`` (k, 3) and ``phi``, ``phi_prime``, ``beta_0``, ``n`` (k,).
    """
    k = len(rows)
    e = np.empty((k, 3))
    s_in = np.empty((k, 3))
    s_out = np.empty((k, 3))
    phi = np.empty(k)
    phi_prime = np.empty(k)
    beta_0 = np.empty(k)
    n = np.empty(k)
    for r in range(k):
        (e0, e1, e2, si0, si1, si2, so0, so1, so2, phi[r], phi_prime[r], beta_0[r],
         n[r]) = _wedge_core(vertices, rows[r], j, dihedron[r], face_0[r], face_n[r], direction, face_direction)
        e[r, 0], e[r, 1], e[r, 2] = e0, e1, e2
        s_in[r, 0], s_in[r, 1], s_in[r, 2] = si0, si1, si2
        s_out[r, 0], s_out[r, 1], s_out[r, 2] = so0, so1, so2
    return e, s_in, s_out, phi, phi_prime, beta_0, n


@numba.njit(cache=True, nogil=True, inline="always")
def _wedge_core(vertices, i, j, d, f0, fn, direction, face_direction):
    """One row of :func:`wedge_geometry`: ``(e, s_in, s_out`` as 3 scalars each``, phi,
    phi_prime, beta_0, n)`` of the diffraction at interaction ``j`` of path ``i``."""
    return _wedge_scalars(direction[d, 0], direction[d, 1], direction[d, 2], face_direction[f0, 0],
                          face_direction[f0, 1], face_direction[f0, 2], face_direction[fn, 0], face_direction[fn, 1],
                          face_direction[fn, 2], vertices[i, j, 0], vertices[i, j, 1], vertices[i, j, 2],
                          vertices[i, j + 1, 0], vertices[i, j + 1, 1], vertices[i, j + 1, 2], vertices[i, j + 2, 0],
                          vertices[i, j + 2, 1], vertices[i, j + 2, 2])


@numba.njit(cache=True, nogil=True, inline="always")
def _wedge_scalars(e0, e1, e2, x0, x1, x2, w0, w1, w2, v0, v1, v2, p0, p1, p2, n0, n1, n2):
    # _wedge_core from scalars: the edge e, the 0-face and n-face directions x and w, the previous
    # vertex v, the diffraction point p and the next vertex n
    y0, y1, y2 = e1 * x2 - e2 * x1, e2 * x0 - e0 * x2, e0 * x1 - e1 * x0
    a0, a1, a2 = v0 - p0, v1 - p1, v2 - p2  # prev - p
    b0, b1, b2 = n0 - p0, n1 - p1, n2 - p2  # nxt - p
    la = math.sqrt(a0 * a0 + a1 * a1 + a2 * a2)
    lb = math.sqrt(b0 * b0 + b1 * b1 + b2 * b2)
    la = la if la > 0.0 else 1.0
    lb = lb if lb > 0.0 else 1.0
    si0, si1, si2 = -a0 / la, -a1 / la, -a2 / la  # unit(p - prev)
    so0, so1, so2 = b0 / lb, b1 / lb, b2 / lb
    w = _angle(w0, w1, w2, x0, x1, x2, y0, y1, y2)
    nn = (2.0 * math.pi if w < 1e-9 else w) / math.pi
    pp = _angle(a0, a1, a2, x0, x1, x2, y0, y1, y2)
    ph = _angle(b0, b1, b2, x0, x1, x2, y0, y1, y2)
    c0, c1, c2 = si1 * e2 - si2 * e1, si2 * e0 - si0 * e2, si0 * e1 - si1 * e0
    b = math.atan2(math.sqrt(c0 * c0 + c1 * c1 + c2 * c2), si0 * e0 + si1 * e1 + si2 * e2)
    return e0, e1, e2, si0, si1, si2, so0, so1, so2, ph, pp, b, nn


# ---- the whole chain of a path in one pass --------------------------------------------------
REFLECTION = 1  # wavepaths.search.paths.InteractionType
DIFFRACTION = 2


@numba.njit(cache=True, nogil=True)
def _chain_rows(lo, hi, addr, E, spreading, deferred, vertices, seg, interactions, primitive, wedge_faces, poly_normal,
                poly_material, direction, face_direction, face_material, kinds, etas, thick, slab, k, floor, delta,
                boundary_eps):
    # wavepaths.fields.chain.path_field_vectors for rows lo to hi, with the kernels above; see
    # chain_fields. The arrays are read here and the helpers take scalars: an array passed to an
    # inlined helper is reference-counted (two atomic operations) at every call
    D = interactions.shape[1]
    P = E.shape[1]
    for r in range(lo, hi):
        total = 0.0
        for s in range(D + 1):  # left to right, as numpy's sum over fewer than 8 columns
            total += seg[r, s]
        if not total > 0.0:
            deferred[r] = True  # a path of length 0: the numpy chain's 1 / 0
            continue
        spreading[r] = 1.0 / total
        for j in range(D):
            kind = interactions[r, j]
            if kind == REFLECTION:
                l0 = seg[r, j] if seg[r, j] > 0 else 1.0
                l1 = seg[r, j + 1] if seg[r, j + 1] > 0 else 1.0
                p = primitive[r, j]
                m = poly_material[p]
                r_te, r_tm, s0, s1, s2, pi0, pi1, pi2, pr0, pr1, pr2 = _reflect_coeffs(
                    (vertices[r, j + 1, 0] - vertices[r, j, 0]) / l0,
                    (vertices[r, j + 1, 1] - vertices[r, j, 1]) / l0,
                    (vertices[r, j + 1, 2] - vertices[r, j, 2]) / l0,
                    (vertices[r, j + 2, 0] - vertices[r, j + 1, 0]) / l1,
                    (vertices[r, j + 2, 1] - vertices[r, j + 1, 1]) / l1,
                    (vertices[r, j + 2, 2] - vertices[r, j + 1, 2]) / l1,
                    poly_normal[p, 0], poly_normal[p, 1], poly_normal[p, 2], kinds[m], etas[m], thick[m], slab)
                for q in range(P):
                    x0, x1, x2 = E[r, q, 0], E[r, q, 1], E[r, q, 2]
                    es = r_te * (x0 * s0 + x1 * s1 + x2 * s2)
                    ep = r_tm * (x0 * pi0 + x1 * pi1 + x2 * pi2)
                    E[r, q, 0] = es * s0 + ep * pr0
                    E[r, q, 1] = es * s1 + ep * pr1
                    E[r, q, 2] = es * s2 + ep * pr2
            elif kind == DIFFRACTION:
                f0, fn = wedge_faces[r, 0], wedge_faces[r, 1]
                d = primitive[r, j]
                (e0, e1, e2, a0, a1, a2, o0, o1, o2, ph, pp, b0, nn) = _wedge_scalars(
                    direction[d, 0], direction[d, 1], direction[d, 2], face_direction[f0, 0], face_direction[f0, 1],
                    face_direction[f0, 2], face_direction[fn, 0], face_direction[fn, 1], face_direction[fn, 2],
                    vertices[r, j, 0], vertices[r, j, 1], vertices[r, j, 2], vertices[r, j + 1, 0],
                    vertices[r, j + 1, 1], vertices[r, j + 1, 2], vertices[r, j + 2, 0], vertices[r, j + 2, 1],
                    vertices[r, j + 2, 2])
                s_before = seg[r, 0]
                for s in range(1, j + 1):
                    s_before += seg[r, s]
                s_after = 0.0
                for s in range(j + 1, D + 1):
                    s_after += seg[r, s]
                # wavepaths.fields.chain._on_boundary_sides: near a shadow or reflection boundary the
                # term takes the side of the geometrical-optics path, which needs the other paths: left
                # to the numpy chain, as are angles the UTD refuses
                margin = max(delta / max(min(s_before, s_after), 1e-300), boundary_eps)
                if (abs(abs(ph - pp) - math.pi) < margin or abs(ph + pp - math.pi) < margin
                        or abs(ph + pp - (2 * nn - 1) * math.pi) < margin):
                    deferred[r] = True
                    break
                if not (math.isfinite(ph) and math.isfinite(pp) and math.isfinite(b0) and 1.0 < nn <= 2.0):
                    deferred[r] = True
                    break
                if not (s_before > 0.0 and s_after > 0.0):
                    deferred[r] = True  # an edge at an end of the path: the numpy chain's 1 / 0
                    break
                if pp > ph:
                    # wavepaths.fields.chain._reciprocal_face_order: the faces exchanged, so that
                    # phi' <= phi (Luebbers' coefficient reciprocal)
                    f0, fn = fn, f0
                    ph, pp = nn * math.pi - ph, nn * math.pi - pp
                    e0, e1, e2 = -e0, -e1, -e2
                    b0 = math.pi - b0
                sin_b = max(abs(math.sin(b0)), floor)
                L = s_before * s_after / (s_before + s_after) * sin_b ** 2
                if not (L >= 0.0 and math.isfinite(L)):
                    deferred[r] = True
                    break
                m0, mn = face_material[f0], face_material[fn]
                (j00, j01, j10, j11, bi0, bi1, bi2, pi0, pi1, pi2, bo0, bo1, bo2, po0, po1,
                 po2) = _diffract_coeffs(addr, e0, e1, e2, a0, a1, a2, o0, o1, o2, face_direction[f0, 0],
                                         face_direction[f0, 1], face_direction[f0, 2],
                                         (face_direction[fn, 0], face_direction[fn, 1], face_direction[fn, 2]), ph,
                                         pp, b0, nn, L, k, floor, kinds[m0], etas[m0], thick[m0], kinds[mn],
                                         etas[mn], thick[mn], slab)
                for q in range(P):  # _diffract_core's loop, written out: an array given to a helper is
                    # reference-counted at every call (two atomic operations per array and path)
                    x0, x1, x2 = E[r, q, 0], E[r, q, 1], E[r, q, 2]
                    cb = x0 * bi0 + x1 * bi1 + x2 * bi2
                    cp = x0 * pi0 + x1 * pi1 + x2 * pi2
                    ob = j00 * cb + j01 * cp
                    op = j10 * cb + j11 * cp
                    E[r, q, 0] = ob * bo0 + op * po0
                    E[r, q, 1] = ob * bo1 + op * po1
                    E[r, q, 2] = ob * bo2 + op * po2
                spreading[r] = 1.0 / math.sqrt(s_before * s_after * (s_before + s_after))


CHAIN_CHUNK = 256
"""Paths per call of :func:`_chain_rows` on numba's threads."""


@numba.njit(cache=True, nogil=True)
def chain_fields(addr, E, spreading, deferred, vertices, seg, interactions, primitive, wedge_faces, poly_normal,
                 poly_material, direction, face_direction, face_material, kinds, etas, thick, slab, k, floor, delta,
                 boundary_eps):
    """:func:`wavepaths.fields.chain.path_field_vectors` (model ``"utd"``, no compat) in one pass
    per path: the reflections (:func:`reflect`), the wedge geometry (:func:`wedge_geometry`)
    and the diffraction (:func:`diffract`) of each interaction in path order, in place on
    ``E`` (N, P, 3), the spreading factor into ``spreading`` (N,).

    ``seg`` (N, D + 1) the segment lengths (``Paths.segment_lengths``); ``face_material``
    the material of each dihedron face. A diffraction within ``delta / min(s, s')``
    (at least ``boundary_eps``) of a shadow or reflection boundary, or with angles the UTD
    refuses, marks the path ``deferred`` and leaves its row: the numpy chain takes it.
    """
    _chain_rows(0, E.shape[0], addr, E, spreading, deferred, vertices, seg, interactions, primitive, wedge_faces,
                poly_normal, poly_material, direction, face_direction, face_material, kinds, etas, thick, slab, k,
                floor, delta, boundary_eps)


@numba.njit(cache=True, nogil=True, parallel=True)
def chain_fields_parallel(addr, E, spreading, deferred, vertices, seg, interactions, primitive, wedge_faces,
                          poly_normal, poly_material, direction, face_direction, face_material, kinds, etas, thick,
                          slab, k, floor, delta, boundary_eps):
    """:func:`chain_fields` with the paths on numba's threads (each path is independent)."""
    n = E.shape[0]
    for c in numba.prange((n + CHAIN_CHUNK - 1) // CHAIN_CHUNK):
        _chain_rows(c * CHAIN_CHUNK, min(n, (c + 1) * CHAIN_CHUNK), addr, E, spreading, deferred, vertices, seg,
                    interactions, primitive, wedge_faces, poly_normal, poly_material, direction, face_direction,
                    face_material, kinds, etas, thick, slab, k, floor, delta, boundary_eps)
