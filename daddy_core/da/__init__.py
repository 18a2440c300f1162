"""Differential algebra: truncated Taylor polynomials, batched over numpy arrays.

    from daddy_core import da
    x = da.variables([1.0, 2.0], order=2)      # x0 = 1 + dx0, x1 = 2 + dx1
    f = da.sqrt(x[0] * x[1])                    # a DA; f.cons, f.gradient(), f.hessian()
    da.evaluate(f, [0.1, -0.2])                 # the polynomial at a displaced point
"""
from .core import DA, constant, variables
from .functions import (arctan, arctan2, concatenate, cons, cos, dot, exp, hypot, log, norm, sin,
                        sqrt, stack, tan, vector, where)
from .maps import compose, evaluate, monomial_values, radius, shift
from .monomials import tables

__all__ = [
    "DA", "constant", "variables", "tables",
    "arctan", "arctan2", "concatenate", "cons", "cos", "dot", "exp", "hypot", "log", "norm",
    "sin", "sqrt", "stack", "tan", "vector", "where",
    "compose", "evaluate", "monomial_values", "radius", "shift",
]
