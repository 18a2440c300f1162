"""Problem data: the paper's catalogue of cases and (later) the Problem definition."""
from .catalogue import Case, case_from_dict, list_cases, load_case

__all__ = ["Case", "case_from_dict", "list_cases", "load_case"]
