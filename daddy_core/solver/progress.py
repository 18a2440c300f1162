"""What a solve reports while it runs: progress lines that carry their figures."""
from __future__ import annotations


class ProgressLine(str):
    """A progress line (a str: printed as it is) with the figures it reports, for programs that
    show a solve's progress (``figures``: homotopy_step and homotopy_steps on a homotopy step's
    line; aul_iteration, ddp_iterations, cost and max_violation on an AUL iteration's)."""

    figures: dict

    def __new__(cls, text: str, **figures):
        line = super().__new__(cls, text)
        line.figures = figures
        return line
