"""Convex programmes on a plan's thrust corrections with every stage's thrust within a rating,
for many draws at once (the campaign model's re-plans, ``campaign_prediction``).

A stage i flies the thrust U_i + c_i s_i [normalised]: the plan's U_i (3,), the correction c_i
(3,) in the scaled units of ``policy.correction_scale`` (s_i per stage). Its rating is a ball
|U_i + c_i s_i| <= R about -U_i / s_i in the scaled units, radius R / s_i: the product of the
stages' balls is the feasible set, and the rows the programmes meet or approach are linear in
the corrections' change d (S draws, 3 * stages columns). Projections onto the balls are radial
(``within``); the programmes are solved for all draws at once, each to its own tolerance.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

NU = 3   # thrust components per stage


@dataclass(frozen=True)
class ThrustBalls:
    """The stages' thrust balls: the plan's thrust ``thrust`` (3 * stages,) [normalised] and
    each column's scale ``scale`` (3 * stages,), one value per stage repeated."""
    thrust: np.ndarray
    scale: np.ndarray

    def thrust_of(self, c: np.ndarray) -> np.ndarray:
        """(S, stages, 3) the thrust flown with the scaled corrections c (S, 3 * stages)."""
        return (self.thrust + c * self.scale).reshape(len(c), len(self.thrust) // NU, NU)

    def within(self, c: np.ndarray, rating: float) -> np.ndarray:
        """The scaled corrections c (S, 3 * stages) with each stage's thrust scaled back onto
        ``rating`` where it passes it (the nearest such thrust)."""
        u = self.thrust_of(c)
        norm = np.linalg.norm(u, axis=2, keepdims=True)
        u = np.where(norm > rating, u * rating / np.maximum(norm, 1e-300), u)
        return (u.reshape(c.shape) - self.thrust) / self.scale

    def row_tolerance(self, A: np.ndarray, rating: float, tol: float = 1e-9) -> float:
        """How near rows d A^T count as met: ``tol`` of what a change of the rating moves
        them by."""
        return tol * rating * float(np.abs(A / self.scale).max())

    def least_change(self, A: np.ndarray, b: np.ndarray, kept: np.ndarray, rating: float,
                     iterations: int = 40, tol: float = 1e-9):
        """(S, 3 * stages) the least scaled change d to the corrections kept (S, 3 * stages)
        with d A^T = b (S, m) and every stage's thrust |U_i + (kept_i + d_i) s_i| within
        ``rating``, and (S,) which draws it exists for. A convex programme per draw, solved
        for all at once on its dual: with multipliers lam (S, m) of the rows, d = P(lam A),
        the projection onto the thrust balls, maximises the concave, once differentiable
        g(lam) = lam.b - |lam A|^2 / 2 + dist(lam A, balls)^2 / 2, whose gradient is the rows'
        miss b - d A^T; semismooth Newton steps (the projection's generalised Jacobian) with
        backtracking, each draw until its rows are met to ``tol`` of what the rating moves
        them. A draw is out of reach when lam.b exceeds the support function of the rows the
        balls reach (lam separates b from them: Boyd & Vandenberghe 2004, section 5.8), or
        after ``iterations``."""
        S, m = b.shape
        stages = A.shape[1] // NU
        A3 = A.reshape(m, stages, NU)
        AA = np.einsum("mjc,ljc->jml", A3, A3).reshape(stages, -1)      # (stages, m * m)
        row_tol = self.row_tolerance(A, rating, tol)
        radius = rating / self.scale[::NU]                              # (stages,) scaled
        centre = -(self.thrust / self.scale + kept).reshape(S, stages, NU)   # of the balls
        lam, d = np.zeros((S, m)), np.zeros_like(kept)
        met = np.zeros(S, bool)

        def dual(i, lam):
            x = lam @ A
            p = self.within(kept[i] + x, rating) - kept[i]
            return np.einsum("sm,sm->s", lam, b[i]) - 0.5 * np.einsum("sn,sn->s", x, x) + \
                0.5 * np.einsum("sn,sn->s", x - p, x - p), p

        todo = np.arange(S)
        for _ in range(iterations):
            if not todo.size:
                break
            i = todo
            now, d[i] = dual(i, lam[i])
            miss = b[i] - d[i] @ A.T
            met[i] = np.abs(miss).max(axis=1) <= row_tol
            Al = np.einsum("mjc,sm->sjc", A3, lam[i])                  # (s, stages, 3)
            support = np.einsum("sjc,sjc->s", Al, centre[i]) + \
                np.linalg.norm(Al, axis=2) @ radius
            apart = np.einsum("sm,sm->s", lam[i], b[i]) > \
                support + row_tol * np.abs(lam[i]).sum(axis=1)
            on = ~met[i] & ~apart
            i, miss, now, todo = i[on], miss[on], now[on], i[on]
            if not i.size:
                break
            # the projection's Jacobian per stage: I inside the ball, f (I - n n^T) outside
            u = self.thrust_of(kept[i] + lam[i] @ A)
            norm = np.maximum(np.linalg.norm(u, axis=2), 1e-300)
            outside = norm > rating
            f = np.where(outside, rating / norm, 1.0)
            An = np.einsum("mjc,sjc->sjm", A3, u / norm[:, :, None])
            H = (f @ AA).reshape(-1, m, m) - np.einsum("sj,sjm,sjl->sml", f * outside, An, An)
            H += 1e-12 * np.trace(H, axis1=1, axis2=2)[:, None, None] * np.eye(m)
            step = np.linalg.solve(H, miss[:, :, None])[:, :, 0]
            slope = np.einsum("sm,sm->s", miss, step)
            alpha = np.ones(len(i))
            short = np.arange(len(i))                 # backtracking, on the draws still short
            for _ in range(30):
                trial = dual(i[short], lam[i[short]] + alpha[short, None] * step[short])[0]
                short = short[~(trial >= now[short] + 1e-4 * alpha[short] * slope[short])]
                if not short.size:
                    break
                alpha[short] *= 0.5
            lam[i] += alpha[:, None] * step
        return d, met

    def nearest(self, A: np.ndarray, b: np.ndarray, start: np.ndarray, kept: np.ndarray,
                rating: float, gap: float = 1e-4) -> np.ndarray:
        """(S, 3 * stages) the change d to the corrections kept (S, 3 * stages) that brings the
        rows d A^T nearest to b (S, rows), least squares, with every stage's thrust within the
        rating, from a change ``start`` within the rating. A convex programme per draw, solved
        for all at once by a barrier method (Boyd & Vandenberghe 2004, sections 9.5 and 11.3:
        Newton steps from 0.99 of the longest step inside the balls, backtracking; the
        objective's weight raised twentyfold from a gap of 1 % of the start's squared miss
        until the barrier's duality gap is below ``gap`` of it)."""
        S, n = start.shape
        if not S:
            return start
        stages = n // NU
        s3 = self.scale.reshape(stages, NU)                        # thrust per unit of y = d
        AtA = A.T @ A
        u0 = self.thrust_of(kept + start)
        r0 = start @ A.T - b                                       # (S, rows) the start's miss
        miss2 = np.einsum("sr,sr->s", r0, r0)
        far = miss2 > self.row_tolerance(A, rating) ** 2
        # the objective over the start's squared miss; a start that meets b stays
        w = 1.0 / np.where(far, miss2, 1.0)[:, None]
        R2 = (np.maximum(rating, np.linalg.norm(u0, axis=2).max(axis=1)) *
              (1 + 1e-6))[:, None] ** 2                            # (S, 1) a strict interior
        y = np.zeros((S, n))

        def thrust(i, y):
            return u0[i] + y.reshape(len(i), stages, NU) * s3

        def merit(i, y, t):
            r = r0[i] + y @ A.T
            slack = R2[i] - np.sum(thrust(i, y) ** 2, axis=2)
            with np.errstate(invalid="ignore", divide="ignore"):
                barrier = -np.log(slack).sum(axis=1)
            return np.where((slack > 0).all(axis=1),
                            0.5 * t * w[i, 0] * np.einsum("sr,sr->s", r, r) + barrier, np.inf)

        t = 100.0 * stages                   # the gap starts at 1 % of the start's squared miss
        while True:
            todo = np.flatnonzero(far)
            value = merit(np.arange(S), y, t)
            for _ in range(50):                                   # Newton on t f + barrier
                if not todo.size:
                    break
                i, yi = todo, y[todo]
                u = thrust(i, yi)                                 # (s, stages, 3)
                inv = 1.0 / (R2[i] - np.sum(u * u, axis=2))       # (s, stages) 1 / slack
                si = s3 * u * inv[:, :, None]                     # d|u|^2/2 / dy / slack
                tw = t * w[i]
                grad = tw * ((r0[i] + yi @ A.T) @ A) + 2 * si.reshape(len(i), n)
                # the barrier's Hessian: 2 s^2 / slack on the diagonal, 4 (s u / slack) outer
                # itself in each stage's block
                H = tw[:, :, None] * AtA
                diagonal = H.reshape(len(i), -1)[:, ::n + 1]      # a view of each diagonal
                diagonal += (2 * (inv[:, :, None] * (s3 * s3))).reshape(len(i), n)
                blocks = H.reshape(len(i), stages, NU, stages, NU)
                outer = 4 * (si[:, :, :, None] * si[:, :, None, :])
                for j in range(stages):
                    blocks[:, j, :, j, :] += outer[:, j]
                diagonal += 1e-12 * np.trace(H, axis1=1, axis2=2)[:, None]
                step = -np.linalg.solve(H, grad[:, :, None])[:, :, 0]
                decrement = -np.einsum("sk,sk->s", grad, step)
                # the longest step inside every ball (|u + a du|^2 = R^2), 1 at most
                du = step.reshape(len(i), stages, NU) * s3
                qa, qb = np.sum(du * du, axis=2), np.sum(u * du, axis=2)
                room = (-qb + np.sqrt(qb * qb + qa / inv)) / np.maximum(qa, 1e-300)
                alpha = np.minimum(1.0, 0.99 * room.min(axis=1))
                trial = np.full(len(i), np.inf)
                short = np.arange(len(i))             # backtracking, on the draws still short
                for _ in range(30):
                    trial[short] = merit(i[short], yi[short] + alpha[short, None] * step[short], t)
                    short = short[~(trial[short] <= value[i[short]] -
                                    0.25 * alpha[short] * decrement[short])]
                    if not short.size:
                        break
                    alpha[short] *= 0.5
                moved = np.ones(len(i), bool)
                moved[short] = False
                y[i[moved]] = yi[moved] + alpha[moved, None] * step[moved]
                value[i[moved]] = trial[moved]
                todo = i[moved & (decrement > 1e-8)]
            if stages / t <= gap:      # the duality gap of the centred point
                return start + y
            t *= 20.0
