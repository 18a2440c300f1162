"""The small dense linear algebra of a backward sweep: (Q_uu + rho I)^-1 by Cholesky on the
nu x nu entries (unrolled for a 3-vector thrust), and the trust-region solution of the shifted
subproblem (every stage's step bounded by a radius)."""
from __future__ import annotations

import math

import numpy as np


def regularised_inverse(Quu: np.ndarray, rho: float) -> np.ndarray | None:
    """(Quu + rho I)^-1 from its Cholesky factor L (M^-1 = L^-T L^-1), or None when Quu + rho I
    is not positive definite (or not finite). Plain Python on the nu x nu entries (the lower
    triangle is read): for nu x nu blocks numpy's cholesky + solve cost more in call overhead
    than the arithmetic, and the 3 x 3 case (a thrust vector) is unrolled."""
    if Quu.shape == (3, 3):
        return _regularised_inverse_3(Quu, rho)
    A = Quu.tolist()
    n = len(A)
    L = [[0.0] * n for _ in range(n)]
    for i in range(n):
        Li = L[i]
        for j in range(i + 1):
            Lj = L[j]
            t = 0.0   # (explicit loops: a generator sum() per entry cost 40 % more)
            for m in range(j):
                t += Li[m] * Lj[m]
            s = A[i][j] - t
            if i == j:
                s += rho
                if not (s > 0.0 and math.isfinite(s)):
                    return None
                Li[i] = math.sqrt(s)
            else:
                Li[j] = s / Lj[j]
    inv = [[0.0] * n for _ in range(n)]   # L^-1, lower triangular
    for i in range(n):
        Li, d = L[i], 1.0 / L[i][i]
        inv[i][i] = d
        for j in range(i):
            t = 0.0
            for m in range(j, i):
                t += Li[m] * inv[m][j]
            inv[i][j] = -t * d
    Linv = np.array(inv)
    return Linv.T @ Linv


def _regularised_inverse_3(Quu: np.ndarray, rho: float) -> np.ndarray | None:
    """``_regularised_inverse`` for a 3 x 3 Quu (a thrust vector), unrolled: the same L and
    L^-1 operations; M^-1 = L^-T L^-1 summed in Python instead of numpy's matmul."""
    (a00, _, _), (a10, a11, _), (a20, a21, a22) = Quu.tolist()
    s0 = a00 + rho
    if not (s0 > 0.0 and math.isfinite(s0)):
        return None
    l00 = math.sqrt(s0)
    l10, l20 = a10 / l00, a20 / l00
    s1 = a11 - l10 * l10 + rho
    if not (s1 > 0.0 and math.isfinite(s1)):
        return None
    l11 = math.sqrt(s1)
    l21 = (a21 - l20 * l10) / l11
    s2 = a22 - (l20 * l20 + l21 * l21) + rho
    if not (s2 > 0.0 and math.isfinite(s2)):
        return None
    i00, i11, i22 = 1.0 / l00, 1.0 / l11, 1.0 / math.sqrt(s2)   # L^-1, lower triangular
    i10 = -(l10 * i00) * i11
    i21 = -(l21 * i11) * i22
    i20 = -(l20 * i00 + l21 * i10) * i22
    m01, m02, m12 = i10 * i11 + i20 * i21, i20 * i22, i21 * i22
    return np.array([[i00 * i00 + i10 * i10 + i20 * i20, m01, m02],
                     [m01, i11 * i11 + i21 * i21, m12],
                     [m02, m12, i22 * i22]])


def trust_region_inverse(Quu: np.ndarray, Qu: np.ndarray, rho: float,
                          radius: float) -> np.ndarray:
    """(Quu + lam I)^-1 with the shift lam >= rho that puts the step -(Quu + lam I)^-1 Qu on the
    trust-region boundary |a| = radius (the trust-region subproblem min Qu.a + a.Quu.a / 2,
    |a| <= radius, of HDDP and the many-revolution DDP paper's section III.F; Quu + rho I is
    positive definite and its step is outside the region, or Quu indefinite). The shift solves the secular
    equation 1/|a(lam)| = 1/radius by Newton's method (Conn, Gould & Toint Alg. 7.3.4's
    iteration; nearly linear in lam, so a few iterations reach 1e-3 of the radius): unlike
    a rescaled Newton step it turns the step towards the gradient where Quu is ill-conditioned,
    and the feedback gains b_k use the same shifted Hessian."""
    if not radius > 0.0:   # no step at all: (Quu + inf I)^-1 (the test that stops DDP follows)
        return np.zeros_like(Quu)
    w, V = np.linalg.eigh(Quu)
    g = V.T @ Qu
    # an indefinite Quu + rho I (``backward_sweep``'s indefinite stages): the boundary step has
    # lam > -w_min (Conn, Gould & Toint Thm 7.2.1), and Newton's iteration from just above
    # -w_min rises monotonically to it
    lam = max(rho, -float(w[0]) + 1e-9 * max(1.0, float(np.max(np.abs(w)))))
    for _ in range(30):
        d = w + lam
        s2 = float(np.sum((g / d) ** 2))
        s = math.sqrt(s2)
        if s <= radius * (1.0 + 1e-3):
            break
        ds = -float(np.sum(g * g / d ** 3)) / s           # d|a|/d lam
        if not ds < 0.0:   # underflow (a radius near round-off): the ratio test rejects it
            break
        lam -= (1.0 / radius - 1.0 / s) * s2 / ds
    return (V / (w + lam)) @ V.T
