"""DADDy solver: DDP variants, augmented Lagrangian, fuel homotopy, Newton polishing."""
from .newton import preload
from .options import (METHODS, Globalization, Method, MultiplierUpdate, SolverOptions, Sweep,
                      case_options)
from .results import Status
from .solution import Solution, WarmStart
from .solve import repropagation_miss, solve

__all__ = ["METHODS", "Globalization", "Method", "MultiplierUpdate", "SolverOptions", "Solution",
           "Status", "Sweep", "WarmStart", "case_options", "preload", "repropagation_miss", "solve"]
