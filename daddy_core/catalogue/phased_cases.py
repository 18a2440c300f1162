"""Multi-phase cases as data (issue 46): a case file's ``phases`` list, built into
``phases.multi_phase``'s problem.

A phased case is a ``double_integrator`` case (the phases are plain stage functions, the
restriction of ``phases``) whose top-level ``stages`` / ``stage_duration`` are replaced by::

    "phases": [
      {"name": "one", "stages": 5, "stage_duration": 1.0,
       "link": {"jump": [0, 0, 0, 0, 0, 0]}},
      {"name": "two", "stages": 5, "stage_duration": 1.0,
       "start": {"lower": -50, "upper": 50, "guess": 0}}
    ]

- ``start`` (optional; not on the first phase, which starts at ``x0``): the phase starts at
  its own static parameters, one per state component, named ``<phase>.x<i>``, with bounds
  ``lower`` / ``upper`` and a ``guess`` (numbers, or lists of one per component). Without it
  the phase carries on from the previous phase's end.
- ``link`` (optional; not on the last phase): psi = x_start(next) - x_end - jump = 0, a
  continuity when ``jump`` is zero, an impulse (a velocity jump at a flyby) otherwise. The next
  phase must have a ``start``: a phase that carries on from this one's end already joins it.

The stages, costs and terminal condition are the double integrator's (``paper_problems``).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..da import functions as dm
from ..dynamics.models import double_integrator_step
from ..errors import DaddyError
from ..phases import Phase, multi_phase
from ..problem import Problem
from ..static_parameters import StaticParameter
from .cases import _known_keys

PHASE_KEYS = ("name", "stages", "stage_duration", "start", "link")
START_KEYS = ("lower", "upper", "guess")
LINK_KEYS = ("jump",)
NX = 6   # the double integrator's [r, v]


@dataclass(frozen=True)
class PhaseSpec:
    """One phase of a case file, validated. ``start``: (lower, upper, guess), each (6,), or
    None; ``jump``: the link's (6,) jump, or None (no link)."""

    name: str
    stages: int
    stage_duration: float
    start: tuple | None = None
    jump: np.ndarray | None = None

    @property
    def parameter_names(self) -> list[str]:
        return [f"{self.name}.x{i}" for i in range(NX)] if self.start is not None else []


def phases_from_list(items, system: str) -> tuple[PhaseSpec, ...]:
    """The case file's ``phases``, validated (a DaddyError naming the field)."""
    if system != "double_integrator":
        raise DaddyError(f"case field 'phases' is built for the double_integrator system (plain "
                         f"stage functions); this case's system is {system!r}")
    if not (isinstance(items, list) and len(items) >= 2):
        raise DaddyError("case field 'phases' must be a list of at least two phase objects")
    specs = []
    for i, d in enumerate(items):
        where = f"phases[{i}]"
        if not isinstance(d, dict):
            raise DaddyError(f"case field '{where}' must be an object")
        _known_keys(d, PHASE_KEYS, f"{where}.")
        name = d.get("name")
        if not (isinstance(name, str) and name and "." not in name):
            raise DaddyError(f"case field '{where}.name' must be a non-empty name without '.', "
                             f"got {name!r}")
        stages = d.get("stages")
        if not (isinstance(stages, int) and not isinstance(stages, bool) and stages >= 1):
            raise DaddyError(f"case field '{where}.stages' must be a positive integer, got "
                             f"{stages!r}")
        dur = d.get("stage_duration")
        if not (isinstance(dur, (int, float)) and dur > 0 and math.isfinite(dur)):
            raise DaddyError(f"case field '{where}.stage_duration' must be a positive number, "
                             f"got {dur!r}")
        start = _start(d["start"], f"{where}.start") if "start" in d else None
        if start is not None and i == 0:
            raise DaddyError(f"case field '{where}.start': the first phase starts at x0")
        jump = _link(d["link"], f"{where}.link") if "link" in d else None
        if jump is not None and i == len(items) - 1:
            raise DaddyError(f"case field '{where}.link': the last phase links to nothing (its "
                             "end is the target)")
        specs.append(PhaseSpec(name, stages, float(dur), start, jump))
    names = [s.name for s in specs]
    if len(set(names)) != len(names):
        raise DaddyError(f"case field 'phases': the phase names must be distinct, got {names}")
    for i, s in enumerate(specs[:-1]):
        if s.jump is not None and specs[i + 1].start is None:
            raise DaddyError(f"case field 'phases[{i}].link': the next phase "
                             f"({specs[i + 1].name!r}) carries on from this one's end; give it "
                             "a 'start' for the link to join")
    return tuple(specs)


def phased_problem(case, stage_cost, terminal_cost, g_teq) -> Problem:
    """``case``'s phases as one ``multi_phase`` problem, every phase with the double
    integrator's Euler stages and ``stage_cost``, the end held by ``terminal_cost`` and
    ``g_teq`` (x, x_target)."""
    every = [name for s in case.phases for name in s.parameter_names]

    def starts(spec):
        at = [every.index(n) for n in spec.parameter_names]
        return lambda w: dm.stack([w[j] for j in at])

    def links(spec):
        jump = spec.jump
        return lambda x_end, x_start, w: dm.stack([x_start[i] - x_end[i] - jump[i]
                                                  for i in range(NX)])
    phases = []
    for s in case.phases:
        params = ()
        if s.start is not None:
            lo, hi, guess = s.start
            params = tuple(StaticParameter(n, lo[i], hi[i], guess[i])
                           for i, n in enumerate(s.parameter_names))
        phases.append(Phase(s.name, np.full(s.stages, s.stage_duration),
                            double_integrator_step, stage_cost, params=params,
                            start=starts(s) if s.start is not None else None,
                            link=links(s) if s.jump is not None else None))
    return multi_phase(case.name, case.x0, case.x_target, phases, terminal_cost, nu=3,
                       g_teq=g_teq)


def _start(d, where: str) -> tuple:
    if not isinstance(d, dict):
        raise DaddyError(f"case field '{where}' must be an object {{\"lower\", \"upper\", "
                         "\"guess\"}")
    _known_keys(d, START_KEYS, f"{where}.")
    for key in ("lower", "upper"):
        if key not in d:
            raise DaddyError(f"case field '{where}.{key}' is missing (a free start needs "
                             "bounds)")
    lo, hi = _per_component(d["lower"], f"{where}.lower"), _per_component(d["upper"],
                                                                          f"{where}.upper")
    if not np.all(lo < hi):
        raise DaddyError(f"case field '{where}': lower must be below upper in every component")
    guess = 0.5 * (lo + hi) if "guess" not in d else _per_component(d["guess"],
                                                                      f"{where}.guess")
    if not np.all((lo <= guess) & (guess <= hi)):
        raise DaddyError(f"case field '{where}.guess' must lie within [lower, upper]")
    return lo, hi, guess


def _link(d, where: str) -> np.ndarray:
    if not isinstance(d, dict):
        raise DaddyError(f"case field '{where}' must be an object {{\"jump\": [6 numbers]}}")
    _known_keys(d, LINK_KEYS, f"{where}.")
    return _per_component(d.get("jump", 0.0), f"{where}.jump")


def _per_component(v, where: str) -> np.ndarray:
    """A number for every component, or a list of NX finite numbers."""
    try:
        a = np.broadcast_to(np.asarray(v, dtype=float), (NX,)).copy()
    except (TypeError, ValueError) as exc:
        raise DaddyError(f"case field '{where}' must be a number or {NX} numbers, got "
                         f"{v!r}") from exc
    if isinstance(v, bool) or not np.all(np.isfinite(a)):
        raise DaddyError(f"case field '{where}' must be finite numbers, got {v!r}")
    return a
