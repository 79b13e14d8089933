"""Non-uniform (GTD) wedge diffraction coefficients in closed form.

The job of this module is the closed-form, boundary-singular references beside the UTD of
:mod:`wavepaths.em.utd`:

* :func:`keller_coefficients`: Keller's GTD PEC wedge coefficient (JOSA 52:116, 1962), the
  ``F -> 1`` limit of Kouyoumjian & Pathak, with its denominators floored on the boundaries;
* :func:`seed_keller_coefficient` and :func:`seed_scalar_radiance`: the seed paper's real
  GTD coefficient and unpolarised diffracted radiance, exactly as written in its section 2.1
  (Aveneau & Meriaux, "Rendering polygonal scenes with diffraction account").

Conventions are those of :mod:`wavepaths.em.utd` (``docs/conventions.md``). The ``"gtd"``
model of :func:`~wavepaths.em.utd.diffraction_jones` is the same limit computed from the
four terms of :mod:`wavepaths.em.utd_terms`, with the faces' ``R``'s.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from wavepaths.em.utd_terms import SIN_BETA_0_FLOOR, Array, WedgeCoefficients, _check_floor, _prepare

__all__ = [
    "keller_coefficients",
    "seed_keller_coefficient",
    "seed_scalar_radiance",
]


def keller_coefficients(
    phi: ArrayLike, phi_prime: ArrayLike, beta_0: ArrayLike, n: ArrayLike, k: ArrayLike,
    *, sin_beta_0_floor: float = SIN_BETA_0_FLOOR, denominator_floor: float = 1e-12,
) -> WedgeCoefficients:
    """Keller's GTD PEC wedge coefficient (JOSA 52:116, 1962), the F -> 1 limit of KP.

    ::

        D_{s,h} = e^{-j pi/4} sin(pi/n) / (n sqrt(2 pi k) sin b0) *
                  [ 1/(cos(pi/n) - cos((phi-phi')/n)) -+ 1/(cos(pi/n) - cos((phi+phi')/n)) ]

    It diverges on the shadow and reflection boundaries: there a denominator smaller than
    ``denominator_floor`` in magnitude is replaced by ``+-denominator_floor``, so the result
    is huge (~1/denominator_floor) but finite. It tends to 0 as ``n -> 1`` (the wedge
    becomes a plane); ``n = 1`` itself is refused, as by every coefficient here.

    Returns
    -------
    WedgeCoefficients
        ``(D_s, D_h)`` [sqrt(m)], complex128 of the broadcast shape.
    """
    _check_floor(sin_beta_0_floor, "sin_beta_0_floor")
    _check_floor(denominator_floor, "denominator_floor")
    p, pp, b0, nn, kk, _ = _prepare(phi, phi_prime, beta_0, n, k, None)
    sb = np.maximum(np.abs(np.sin(b0)), sin_beta_0_floor)
    pref = np.exp(-0.25j * np.pi) * np.sin(np.pi / nn) / (nn * np.sqrt(2.0 * np.pi * kk) * sb)

    def inv(beta: Array) -> Array:
        den = np.cos(np.pi / nn) - np.cos(beta / nn)
        den = np.where(np.abs(den) < denominator_floor, np.where(den < 0, -denominator_floor, denominator_floor), den)
        return 1.0 / den

    a, b = inv(p - pp), inv(p + pp)
    return WedgeCoefficients(pref * (a - b), pref * (a + b))


def seed_keller_coefficient(
    wavelength: ArrayLike, n: ArrayLike, beta: ArrayLike, delta: ArrayLike, alpha: ArrayLike,
    C: ArrayLike,
) -> Array:
    """The seed paper's real GTD coefficient, exactly as written in its section 2.1.

    Aveneau & Meriaux, "Rendering polygonal scenes with diffraction account" (seed 000)::

        D = sqrt(lambda) cos(pi/4) sin(pi/n) / (2 n pi sin beta) *
            [ 1/(cos(pi/n) - cos((delta - alpha)/n)) + C / (cos(pi/n) - cos((delta + alpha + pi)/n)) ]

    ``delta``, ``alpha``: diffracted and incident directions measured from the *normal* of
    the incident face, so ``delta = phi - pi/2``, ``alpha = phi' - pi/2``; ``C = -1`` is
    Keller's soft and ``C = +1`` his hard coefficient. (The seed calls ``C = +1`` its
    ``D_par`` and ``C = -1`` its ``D_perp``: its "parallel" is the hard case, E perpendicular
    to the edge and H along it, which acts on the edge-fixed ``phi`` component. Feeding
    :func:`wavepaths.em.polarization.seed_diffracted_coherence`, whose ``d_par`` acts on the
    ``beta_0`` component, takes the seed's ``D_perp`` as ``d_par``.) The result equals
    ``Re(e^{j pi/4} D_Keller) / sqrt(2)``: Keller's value without its ``e^{-j pi/4}`` phase
    and a factor ``1/sqrt(2)`` smaller in magnitude. No floor: it is infinite on boundaries.
    """
    lam, nn, b, de, al, c = (np.asarray(v, dtype=float) for v in (wavelength, n, beta, delta, alpha, C))
    with np.errstate(divide="ignore"):
        pref = np.sqrt(lam) * np.cos(np.pi / 4) * np.sin(np.pi / nn) / (2 * nn * np.pi * np.sin(b))
        t1 = 1.0 / (np.cos(np.pi / nn) - np.cos((de - al) / nn))
        t2 = c / (np.cos(np.pi / nn) - np.cos((de + al + np.pi) / nn))
    return np.asarray(pref * (t1 + t2))


def seed_scalar_radiance(
    L_inc: ArrayLike, wavelength: ArrayLike, n: ArrayLike, beta: ArrayLike, delta: ArrayLike,
    alpha: ArrayLike,
) -> Array:
    """The seed paper's unpolarised diffracted radiance, exactly as written (section 2.1).

    ::

        L_dif = L_inc lambda ( cos(pi/4) sin(pi/n) / (n pi sin beta (cos(pi/n) - cos((delta-alpha)/n))) )^2

    This is ``4 L_inc D_1^2`` with ``D_1`` the first (incident-boundary) term of
    :func:`seed_keller_coefficient`, i.e. ``2 L_inc |Keller's first term|^2``; the
    polarisation average of Keller's coefficients would be ``|A|^2 + |B|^2`` (first and
    second terms): the seed drops ``B`` and doubles ``|A|^2``.
    """
    li, lam, nn, b, de, al = (np.asarray(v, dtype=float) for v in (L_inc, wavelength, n, beta, delta, alpha))
    with np.errstate(divide="ignore"):
        x = np.cos(np.pi / 4) * np.sin(np.pi / nn) / (
            nn * np.pi * np.sin(b) * (np.cos(np.pi / nn) - np.cos((de - al) / nn))
        )
    return np.asarray(li * lam * x**2)
