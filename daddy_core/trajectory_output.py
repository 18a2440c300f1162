"""A solved trajectory in the forms a mission designer uses: node times, Earth-centred states as
Cartesian ECI and as Keplerian elements, a CSV of every node for any case, and a CCSDS Orbit
Ephemeris Message (OEM 2.0, plain text) for every system with a frame in space.

Earth-centred solutions hold modified equinoctial elements staged in true longitude
(``models.equinoctial_sundman``): node k lies at the true longitude t_start + the stage angles
before it, its time is the state's time component. Other solutions are staged in time and their
states are Cartesian already.

The OEM's frame per system (``oem_segment``):

| system | CENTER_NAME | REF_FRAME |
|---|---|---|
| Earth-centred (equinoctial, sail) | EARTH | EME2000 (the frame of the elements) |
| Sun-centred two-body | SUN | ECLIPJ2000: the paper's states are ecliptic J2000 (interpreted: its Table 3 lists the planets' z within 1e-4 AU of 0) |
| Earth-Moon CR3BP, inertial (default) | EARTH-MOON BARYCENTER | EMB_INERTIAL: the rotating frame's axes at REF_FRAME_EPOCH, held fixed |
| Earth-Moon CR3BP, rotating | EARTH-MOON BARYCENTER | EMB_ROTATING: x from the Earth to the Moon, z along their orbit's angular momentum |

The CR3BP frames are not in the CCSDS/SANA registry (the model's Moon moves on a circle, so no
ephemeris frame is exact for it): their definitions are in the file's COMMENT lines. The
inertial conversion turns the rotating frame about z at the model's mean motion n = 1 / TU:
r_I = R_z(n t) r, v_I = R_z(n t) (v + n z x r).
"""
from __future__ import annotations

import enum
import math
from datetime import datetime, timedelta, timezone
from pathlib import Path

import numpy as np

from .dynamics import models
from .dynamics.units import Units
from .errors import DaddyError

# OEM epochs are absolute; a solution is relative to its start, which --epoch places (default
# J2000, the reference epoch of the EME2000 frame)
J2000 = datetime(2000, 1, 1, 12, 0, 0, tzinfo=timezone.utc)


# the systems whose states are modified equinoctial elements and time (thrust cases: and mass)
EARTH_SYSTEMS = ("earth_equinoctial", "earth_sail")


def is_earth_centred(sol) -> bool:
    """The solution's states are modified equinoctial elements staged in true longitude."""
    return sol.time_index is not None and sol.units.get("system") in EARTH_SYSTEMS


def node_times_s(sol) -> np.ndarray:
    """(N+1,) time of each node since the start [s]."""
    units = Units.from_dict(sol.units)
    if sol.time_index is not None:
        return units.time_s(sol.X[:, sol.time_index] - sol.X[0, sol.time_index])
    return units.time_s(np.concatenate([[0.0], np.cumsum(sol.stage_dt)]))


def node_longitudes(sol) -> np.ndarray:
    """(N+1,) true longitude of each node of an Earth-centred solution [rad]."""
    return sol.t_start + np.concatenate([[0.0], np.cumsum(sol.stage_dt)])


def earth_cartesian_si(sol, X: np.ndarray | None = None) -> np.ndarray:
    """(N+1, 7) Earth-centred inertial states [position m (3), velocity m/s (3), mass kg] of an
    Earth-centred solution ((N+1, 6) without a mass state: a sail) (the frame of its elements: x towards the line of zero right
    ascension of the ascending node); ``X``: other states on the solution's nodes (default
    its own)."""
    units = Units.from_dict(sol.units)
    X = sol.X if X is None else X
    L = node_longitudes(sol)
    rv = models.mee_to_cartesian(X[:, :5].T, L, units.gm).T   # every node at once
    return units.cartesian_si(np.column_stack([rv, X[:, 6:7]]))


def cartesian_repropagation(sol, rhs) -> np.ndarray:
    """(N+1, 7) an Earth-centred solution's thrust (RTN, constant over each stage's time) flown
    in Cartesian coordinates in time from its first node -- DOP853 at rtol = atol = 1e-12
    (``integrators.dop853``), stage by stage over the node times -- in ``X_si``'s units: what
    the spacecraft flies if the schedule is executed by the clock. rhs: the normalised
    Cartesian dynamics with thrust in RTN (``Case.cartesian_rhs``: the model of the elements'
    own physics, J2 included where the case has it)."""
    from .integrators import dop853   # (the integrators import nothing of this module)
    if not is_earth_centred(sol):
        raise DaddyError("cartesian_repropagation: not an Earth-centred solution")
    units = Units.from_dict(sol.units)
    T = sol.X[:, sol.time_index]
    x = np.append(models.mee_to_cartesian(sol.X[0, :5], sol.t_start, units.gm), sol.X[0, 6])
    out = np.empty((sol.N + 1, 7))
    out[0] = x
    for k in range(sol.N):
        x = dop853(rhs, x, sol.U[k], T[k], T[k + 1] - T[k], rtol=1e-12, atol=1e-12)
        out[k + 1] = x
    return units.cartesian_si(out)


def cartesian_miss(sol, rhs) -> dict:
    """How far the Cartesian re-propagation (``cartesian_repropagation``) arrives from the
    solution's own final node: {"position_km", "velocity_m_s", "mass_kg"} (norms of the
    differences). The solution's elements, staged in true longitude, and the flown trajectory,
    integrated in time, are independent computations of one physics: their difference is the
    whole chain's error (transcription, integration, the conversion of elements)."""
    flown = cartesian_repropagation(sol, rhs)[-1]
    end = sol.X_si[-1]
    return {"position_km": float(np.linalg.norm(flown[:3] - end[:3]) / 1000.0),
            "velocity_m_s": float(np.linalg.norm(flown[3:6] - end[3:6])),
            "mass_kg": float(abs(flown[6] - end[6]))}


def earth_elements(sol) -> np.ndarray:
    """(N+1, 6) Keplerian elements of an Earth-centred solution's nodes: a [km], e, i [deg],
    RAAN [deg], argument of perigee [deg], true longitude [deg] (RAAN + argp + true anomaly;
    the angles in [0, 360); RAAN is undefined at i = 0 and argp at e = 0, where these
    values are arbitrary and the true longitude is what locates the spacecraft)."""
    units = Units.from_dict(sol.units)
    p, f, g, h, k = sol.X[:, :5].T
    e = np.hypot(f, g)
    a_km = p / (1.0 - e * e) * units.lu_km
    i = 2.0 * np.arctan(np.hypot(h, k))
    raan = np.arctan2(k, h)
    argp = np.arctan2(g, f) - raan
    return np.column_stack([a_km, e, np.degrees(i), np.degrees(raan) % 360.0,
                            np.degrees(argp) % 360.0, np.degrees(node_longitudes(sol)) % 360.0])


def csv_columns(sol) -> tuple[list[str], np.ndarray]:
    """The CSV's header and (N+1, columns) rows: node k, time [s], the SI state, for
    Earth-centred solutions the Keplerian elements too, then the thrust on stage k [N] and its
    magnitude (blank, NaN, at the last node)."""
    earth = is_earth_centred(sol)
    t = node_times_s(sol)
    if earth:
        state = earth_cartesian_si(sol)
        names = ["x_m", "y_m", "z_m", "vx_m_s", "vy_m_s", "vz_m_s", "mass_kg",
                 "a_km", "e", "i_deg", "raan_deg", "argp_deg", "true_longitude_deg"]
        state = np.column_stack([state, earth_elements(sol)])
    else:
        state = sol.X_si
        n = state.shape[1]
        names = (["x_m", "y_m", "z_m", "vx_m_s", "vy_m_s", "vz_m_s", "mass_kg"][:n] if n in (6, 7)
                 else [f"x{i}" for i in range(n)])
    thrust = np.full((sol.N + 1, sol.U.shape[1]), np.nan)
    thrust[:-1] = sol.thrust_n
    frame = ["u_r_n", "u_t_n", "u_n_n"] if earth else ["u_x_n", "u_y_n", "u_z_n"]
    unames = frame if sol.U.shape[1] == 3 else [f"u{i}" for i in range(sol.U.shape[1])]
    mag = np.append(np.linalg.norm(sol.thrust_n, axis=1), np.nan)
    rows = np.column_stack([np.arange(sol.N + 1), t, state, thrust, mag])
    return ["k", "time_s", *names, *unames, "thrust_n"], rows


def write_csv(sol, path: str | Path) -> None:
    """The trajectory as CSV (``csv_columns``; empty fields where a value does not exist); a
    multi-phase solution phase by phase (``phase_rows``)."""
    if sol.phases:
        write_rows(*phase_rows(sol), path, index_columns=2)
    else:
        write_rows(*csv_columns(sol), path)


def phase_rows(sol) -> tuple[list[str], np.ndarray]:
    """(header, rows) of a multi-phase solution (``Solution.phases``): for each phase its nodes
    from its own start, [phase number, node k within the phase, x (nx), u (nu)], u empty on a
    phase's last node."""
    rows = []
    for i, ph in enumerate(sol.phases):
        X, U = np.asarray(ph["X"], float), np.asarray(ph["U"], float)
        U = np.vstack([U, np.full((1, U.shape[1]), np.nan)])
        rows += [np.concatenate([[i, k], X[k], U[k]]) for k in range(X.shape[0])]
    rows = np.array(rows)
    nx, nu = len(sol.phases[0]["X"][0]), len(sol.phases[0]["U"][0])
    header = (["phase", "k"] + [f"x{j}" for j in range(nx)] + [f"u{j}" for j in range(nu)])
    return header, rows


def write_rows(header: list[str], rows: np.ndarray, path: str | Path,
               index_columns: int = 1) -> None:
    """A CSV of ``rows`` (K, len(header)) whose first ``index_columns`` are integer indices;
    empty fields for NaN."""
    lines = [",".join(header)]
    for r in rows:
        lines.append(",".join(str(int(v)) if j < index_columns
                              else ("" if math.isnan(v) else repr(float(v)))
                              for j, v in enumerate(r)))
    Path(path).write_text("\n".join(lines) + "\n")


class OemFrame(str, enum.Enum):
    """The frame of a CR3BP solution's OEM (module docstring); other systems have one."""

    INERTIAL = "inertial"
    ROTATING = "rotating"

    __str__ = str.__str__


def rotating_to_inertial_si(X_si: np.ndarray, t_s: np.ndarray, tu_s: float) -> np.ndarray:
    """(K, 6) CR3BP states [m, m/s] in the rotating frame at times ``t_s`` [s] since the epoch
    -> the inertial frame whose axes are the rotating frame's at the epoch (module
    docstring); the mean motion is 1 / ``tu_s`` [rad/s]."""
    X_si, n = np.asarray(X_si, float), 1.0 / tu_s
    theta = n * np.asarray(t_s, float)
    c, s = np.cos(theta), np.sin(theta)
    r, v = X_si[:, :3], X_si[:, 3:6]
    v = v + n * np.column_stack([-r[:, 1], r[:, 0], np.zeros(len(r))])   # + n z x r

    def rot(a):
        return np.column_stack([c * a[:, 0] - s * a[:, 1], s * a[:, 0] + c * a[:, 1], a[:, 2]])
    return np.column_stack([rot(r), rot(v)])


def oem_segment(sol, frame: OemFrame = OemFrame.INERTIAL) -> tuple[str, str, list, np.ndarray]:
    """(CENTER_NAME, REF_FRAME, COMMENT lines, (N+1, 6) node states [km, km/s]) of a solution's
    OEM (the module docstring's table). Raises DaddyError for a system without a frame in
    space (the double integrator), or a rotating frame asked of a system without one."""
    system = sol.units.get("system")
    check_oem(system, frame, sol.case)
    if is_earth_centred(sol):
        return "EARTH", "EME2000", [], earth_cartesian_si(sol)[:, :6] / 1000.0
    if system == "sun_two_body":
        return ("SUN", "ECLIPJ2000", ["ecliptic and mean equinox of J2000, Sun-centred (the "
                                      "case's states)"], sol.X_si[:, :6] / 1000.0)
    units = Units.from_dict(sol.units)   # the Earth-Moon CR3BP
    lines = [f"Earth-Moon CR3BP (mass ratio {units.gm:.10g}, Earth-Moon distance "
             f"{units.lu_km:g} km, mean motion {1.0 / units.tu_s:.10e} rad/s), origin the "
             "barycentre", "EMB_ROTATING: x from the Earth to the Moon, z along their "
             "orbit's angular momentum, y completing the right-handed frame"]
    rv = sol.X_si[:, :6]
    if frame is OemFrame.INERTIAL:
        lines.append("EMB_INERTIAL: the axes of EMB_ROTATING at REF_FRAME_EPOCH, held fixed"
                     " (r_I = R_z(n t) r, v_I = R_z(n t) (v + n z x r))")
        rv = rotating_to_inertial_si(rv, node_times_s(sol), units.tu_s)
    return ("EARTH-MOON BARYCENTER", f"EMB_{frame.name}", lines, rv / 1000.0)


OEM_SYSTEMS = (*EARTH_SYSTEMS, "sun_two_body", "earth_moon_cr3bp")


def check_oem(system: str, frame: OemFrame, case: str) -> None:
    """Raises DaddyError unless ``system`` has an OEM in ``frame``."""
    if system not in OEM_SYSTEMS:
        raise DaddyError(f"an OEM needs a frame in space; {case!r} is {system}: write its CSV "
                         "instead")
    if frame is OemFrame.ROTATING and system != "earth_moon_cr3bp":
        raise DaddyError(f"OEM frame {frame}: only Earth-Moon CR3BP solutions have a rotating "
                         f"frame ({case!r} is {system})")


def write_oem(sol, path: str | Path, epoch: datetime = J2000, object_name: str | None = None,
              frame: OemFrame = OemFrame.INERTIAL) -> None:
    """A CCSDS OEM 2.0 (KVN) of a solution: one segment, UTC, the node states in km and km/s
    at the start epoch + the node times, in the system's frame (``oem_segment``; a CR3BP
    solution's inertial or rotating frame)."""
    if epoch.tzinfo is None:
        epoch = epoch.replace(tzinfo=timezone.utc)
    center, ref_frame, notes, rv = oem_segment(sol, frame)
    t = node_times_s(sol)

    def stamp(s: float) -> str:
        return (epoch + timedelta(seconds=float(s))).strftime("%Y-%m-%dT%H:%M:%S.%f")

    name = object_name or sol.case
    lines = ["CCSDS_OEM_VERS = 2.0",
             f"CREATION_DATE = {datetime.now(timezone.utc).strftime('%Y-%m-%dT%H:%M:%S')}",
             "ORIGINATOR = daddy", "", "META_START", f"OBJECT_NAME = {name}",
             f"OBJECT_ID = {name}", f"CENTER_NAME = {center}", f"REF_FRAME = {ref_frame}",
             *([f"REF_FRAME_EPOCH = {stamp(t[0])}"] if ref_frame == "EMB_INERTIAL" else []),
             "TIME_SYSTEM = UTC", f"START_TIME = {stamp(t[0])}", f"STOP_TIME = {stamp(t[-1])}",
             "META_STOP", "", *(f"COMMENT {line}" for line in notes),
             f"COMMENT {sol.method} {'fuel' if sol.fuel_optimal else 'energy'}-optimal, "
             f"converged {sol.converged}"
             + ("" if sol.final_mass_kg is None else f", final mass {sol.final_mass_kg:.3f} kg")]
    lines += [stamp(s) + " " + " ".join(f"{v: .12e}" for v in row) for s, row in zip(t, rv)]
    Path(path).write_text("\n".join(lines) + "\n")
