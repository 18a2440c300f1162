"""How each stage of the solver ended: one ``Status`` enum for control flow and messages, and
the result base class the DDP, AUL and Newton results share."""
from __future__ import annotations

from dataclasses import dataclass
from enum import Enum


class Status(Enum):
    """Why a DDP solve (Alg. 3), an AUL loop (Alg. 4) or a Newton run (Alg. 11) stopped; the
    value is the message reported in ``Solution.reason``."""

    TIME_BUDGET = "time budget exceeded"
    CANCELLED = "cancelled by the caller"
    # DDP
    DDP_CONVERGED = "relative cost decrease below tol_ddp"
    DDP_MAX_ITER = "ddp_max_iter reached"
    QUU_INDEFINITE = "Q_uu not positive definite up to rho_max"
    LINE_SEARCH_FAILED = "line search failed up to rho_max"
    DDP_NOTHING_TO_GAIN = ("no step accepted where the full step's predicted decrease is below "
                           "tol_ddp")
    TRUST_REGION_COLLAPSED = "trust region shrank to round-off"
    DDP_STALLED = ("stalled: ddp_stall_iter steps in a row shorter than ddp_stall_alpha of "
                   "the full step, each lowering the cost by less than tol_ddp")
    # augmented Lagrangian
    AUL_CONVERGED = "max violation below tol_aul"
    AUL_MAX_ITER = "aul_max_iter reached"
    AUL_STALLED = "max violation stalled with the penalty at mu_max"
    AUL_UNMOVED = "max violation unmoved while the penalty grew"
    AUL_DIVERGED = ("DDP diverged from the start: neither the line search nor the trust "
                    "region converged, and the max violation grew a hundredfold")
    # Newton
    NEWTON_CONVERGED = "active constraints below tol_newton"
    NEWTON_MAX_ITER = "newton_max_iter reached"
    NEWTON_NAN = "constraint evaluation produced NaN"
    NEWTON_SINGULAR = "Delta Delta^T is singular"
    NEWTON_NO_DESCENT = "no descent on the constraint model"
    NEWTON_STALLED = ("max residual did not halve over newton_stall_iter iterations or "
                      "stopped moving")
    # KKT polishing
    KKT_CONVERGED = "KKT residual below tol_optimality"
    KKT_MAX_ITER = "kkt_max_iter reached"
    KKT_NO_DESCENT = "no KKT step lowered the cost"
    KKT_STALLED = "the lowest KKT residual did not halve over the stall window"


def not_halved(history: list, k: int) -> bool:
    """The last of ``history`` (a violation or residual after each iteration) is above half the
    one k iterations before (False until there are k + 1 of them, or when k = 0): the test
    behind ``Status.AUL_STALLED``, ``Status.NEWTON_STALLED`` and ``Status.KKT_STALLED``."""
    return 0 < k < len(history) and history[-1] > 0.5 * history[-1 - k]


@dataclass
class StepResult:
    """What every solver stage reports: converged, its iteration count and why it stopped."""

    converged: bool
    iterations: int
    status: Status

    @property
    def reason(self) -> str:
        return self.status.value
