"""The paper's catalogue: its cases as data (``cases/*.json``), their loader, and the problems
built from them."""
from .cases import Case, case_from_dict, list_cases, load_case, load_thrust_case
from .paper_problems import low_thrust_costs, problem_from_case

__all__ = ["Case", "case_from_dict", "list_cases", "load_case", "load_thrust_case", "low_thrust_costs",
           "problem_from_case"]
