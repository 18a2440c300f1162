"""Truth simulation for the closed GNC loop (ROS-free): propagates the real dynamics with the
applied thrust, and models navigation errors (on the published estimate) and execution errors
(thrust magnitude and pointing). SI at the interface, normalised inside."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from daddy_core.catalogue import load_case
from daddy_core.errors import DaddyError

from daddy_ros.self_trigger import propagate

T0_S = 1000.0  # the demo's mission clock at departure [s]; any positive epoch works


@dataclass(frozen=True)
class Errors:
    """1-sigma error levels."""

    nav_pos_m: float = 100.0
    nav_vel_m_s: float = 1e-3
    exec_mag: float = 0.01            # relative thrust magnitude
    exec_point_deg: float = 1.0       # pointing


class TruthSim:
    """The real spacecraft: state in SI, advanced with piecewise-constant applied thrust."""

    def __init__(self, case_name: str, errors: Errors = Errors(), seed: int = 0,
                 t0_s: float = 0.0, initial_offset_si: np.ndarray | None = None,
                 outage_s: tuple[float, float] | None = None):
        """``initial_offset_si``: (6,) the truth's departure state minus the case's [m, m/s]
        (an initial-state dispersion); ``outage_s``: (start, end) on the mission clock [s], an
        interval in which the engine does not fire whatever is commanded (a missed-thrust
        event; guidance is not told). The errors' random stream depends on ``seed`` only."""
        self.case = load_case(case_name)
        self.units = self.case.units
        self.errors = errors
        self.rng = np.random.default_rng(seed)
        self.x = self.case.cartesian_x0()   # normalised Cartesian truth [r, v, m]
        if initial_offset_si is not None and np.any(initial_offset_si):
            x_si = self.units.cartesian_si(self.x)
            x_si[:6] += np.asarray(initial_offset_si, dtype=float)
            self.x = self.units.cartesian_normalised(x_si)
        self.outage_s = outage_s
        self.t_s = t0_s
        self.t0_s = t0_s

    @property
    def tof_s(self) -> float:
        return self.case.tof * self.units.tu_s

    def truth_si(self):
        """(position m, velocity m/s, mass kg) of the truth."""
        x = self.units.cartesian_si(self.x)
        return x[:3], x[3:6], float(x[6])

    def estimate_si(self):
        """A navigation estimate: truth + Gaussian errors (position m, velocity m/s, mass kg)."""
        p, v, m = self.truth_si()
        e = self.errors
        return (p + self.rng.normal(scale=e.nav_pos_m, size=3),
                v + self.rng.normal(scale=e.nav_vel_m_s, size=3), m)

    def apply(self, thrust_n: np.ndarray, dt_s: float) -> np.ndarray:
        """Fly ``dt_s`` with the commanded thrust perturbed by execution errors (and none in an
        outage); returns the thrust actually applied at the start of the step [N]."""
        u = np.asarray(thrust_n, dtype=float)
        mag = np.linalg.norm(u)
        if mag > 0:
            e = self.errors
            axis = np.cross(u, self.rng.normal(size=3))
            axis /= np.linalg.norm(axis)
            ang = np.radians(self.rng.normal(scale=e.exec_point_deg))
            # Rodrigues rotation of u about an axis normal to it
            u = u * np.cos(ang) + np.cross(axis, u) * np.sin(ang)
            u = u * (1.0 + self.rng.normal(scale=e.exec_mag))
            umax = self.case.spacecraft.max_thrust_n
            if np.linalg.norm(u) > umax * 1.05:  # the engine cannot exceed its rating by much
                u *= umax * 1.05 / np.linalg.norm(u)
        pieces = [(dt, u if on else np.zeros(3)) for dt, on in self._engine_windows(dt_s)]
        for dt, thrust in pieces:
            self.x = self.propagate(self.x, thrust, dt)
        self.t_s += dt_s
        return pieces[0][1]

    def _engine_windows(self, dt_s: float) -> list[tuple[float, bool]]:
        """The next ``dt_s`` cut at the outage's edges: (duration s, engine on) per piece."""
        t0, t1 = self.t_s, self.t_s + dt_s
        if self.outage_s is None or not (self.outage_s[0] < t1 and t0 < self.outage_s[1]):
            return [(dt_s, True)]
        cuts = [t0, *[c for c in self.outage_s if t0 < c < t1], t1]
        return [(b - a, not self.outage_s[0] <= 0.5 * (a + b) < self.outage_s[1])
                for a, b in zip(cuts[:-1], cuts[1:])]

    def propagate(self, x: np.ndarray, thrust_n: np.ndarray, dt_s: float) -> np.ndarray:
        """The true dynamics without errors: normalised state x after dt_s under thrust_n [N]."""
        return propagate(self.case, x, thrust_n, dt_s)

    def miss(self):
        """(position miss m, velocity miss m/s) with respect to the case target (a Cartesian
        state: an Earth-centred case's target is an orbit, whose miss is the elements')."""
        if self.case.staged_in_angle:
            raise DaddyError(f"TruthSim.miss: {self.case.name!r} arrives on an orbit, not at a "
                             "state; compare its elements (models.cartesian_to_mee)")
        d = self.deviation_si()
        return float(np.linalg.norm(d[:3])), float(np.linalg.norm(d[3:6]))

    def deviation_si(self) -> np.ndarray:
        """(6,) the truth's position [m] and velocity [m/s] minus the case target's (``miss``)."""
        if self.case.staged_in_angle:
            raise DaddyError(f"TruthSim.deviation_si: {self.case.name!r} arrives on an orbit, "
                             "not at a state")
        return self.units.cartesian_si(self.x - self.case.x_target)[:6]
