"""DADDy solver: DDP variants, augmented Lagrangian, fuel homotopy, Newton polishing."""
from .options import METHODS, SolverOptions, case_options, parse_method
from .solution import Solution
from .solve import repropagation_miss, solve

__all__ = ["METHODS", "SolverOptions", "Solution", "case_options", "parse_method",
           "repropagation_miss", "solve"]
