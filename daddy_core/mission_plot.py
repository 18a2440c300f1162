"""A solved transfer as a mission designer looks at it (one PNG, matplotlib: the plots extra).

Left, the trajectory in 3-D in the case's natural frame, the bodies drawn to scale:

- Earth-Moon CR3BP: the rotating frame about the barycentre [1000 km]; the Moon (and the Earth
  where the view reaches it) as spheres of their mean radii, the Earth's direction marked when
  it lies outside the view;
- Sun-centred two-body: the ecliptic J2000 frame [AU]; the Sun to scale, the departure and
  arrival bodies' orbits (the Keplerian orbits of the case's initial and target states);
- Earth-centred: EME2000 [1000 km]; the Earth to scale, the path coloured by time (the first
  revolutions light, the last dark), so that 1,000+ revolutions stay readable.

Thrust arrows along the path (at most ``MAX_ARROWS`` nodes, length in proportion to the
thrust, the direction in the plot's frame: Earth-centred RTN thrust turned to EME2000).
Right: the thrust magnitude with the thrust bound and the switching structure (thrust arcs
shaded, switches counted; beyond ``DENSE_STAGES`` Earth-centred stages, each revolution's duty
cycle instead), the mass, and the orbit (Earth-centred: a, e, i and RAAN, revolutions on the
top axis; otherwise the distance to the nearest body), against time.
"""
from __future__ import annotations

import numpy as np

from .dynamics.models import rtn_basis
from .dynamics.units import AU_KM, EARTH_RADIUS_KM, MOON_RADIUS_KM, Units
from .errors import DaddyError
from .plotting import _pyplot
from .trajectory_output import is_earth_centred, node_times_s

SUN_RADIUS_KM = 695_700.0          # IAU 2015 nominal solar radius
MAX_ARROWS = 36
THRUST_ON = 0.5                    # a stage thrusts (switching structure) above this * u_max
DENSE_STAGES = 400                 # beyond it an Earth-centred thrust panel shows duty cycles
RAAN_MIN_INCLINATION_DEG = 0.1     # below it the node line, and so the RAAN, is not drawn


def natural_frame(sol) -> tuple[np.ndarray, float, str]:
    """((N+1, 3) node positions in the plot's unit, the unit in km, its label)."""
    system = sol.units.get("system")
    if system == "sun_two_body":
        return sol.X_si[:, :3] / 1000.0 / AU_KM, AU_KM, "AU"
    if system in ("earth_moon_cr3bp", "earth_equinoctial", "earth_sail"):
        return sol.X_si[:, :3] / 1e6, 1000.0, "1000 km"
    raise DaddyError(f"a mission plot needs a frame in space; {sol.case!r} is {system}")


def thrust_in_frame(sol) -> np.ndarray:
    """(N, 3) each stage's thrust [N] in the plot's frame (Earth-centred: RTN at the stage's
    first node turned to EME2000)."""
    u = sol.thrust_n[:, :3]
    if not is_earth_centred(sol):
        return u
    X = sol.X_si
    return np.array([rtn_basis(X[k, :3], X[k, 3:6]) @ u[k] for k in range(sol.N)])


def kepler_orbit(state_km: np.ndarray, gm_km3_s2: float, n: int = 361) -> np.ndarray:
    """(n, 3) points [km] of the conic through a two-body state [km, km/s]: the whole ellipse."""
    r, v = np.asarray(state_km[:3], float), np.asarray(state_km[3:6], float)
    h = np.cross(r, v)
    e_vec = np.cross(v, h) / gm_km3_s2 - r / np.linalg.norm(r)
    e = np.linalg.norm(e_vec)
    p = h @ h / gm_km3_s2
    P = e_vec / e if e > 1e-9 else r / np.linalg.norm(r)
    Q = np.cross(h / np.linalg.norm(h), P)
    nu = np.linspace(0.0, 2 * np.pi, n)
    rad = p / (1 + e * np.cos(nu))
    return rad[:, None] * (np.cos(nu)[:, None] * P + np.sin(nu)[:, None] * Q)


def switches(thrust_on: np.ndarray) -> int:
    """The number of on/off changes of a (N,) boolean thrust sequence."""
    return int(np.count_nonzero(np.diff(thrust_on.astype(int))))


def _sphere(ax, centre, radius, colour, label):
    a, b = np.mgrid[0:2 * np.pi:24j, 0:np.pi:13j]
    ax.plot_surface(centre[0] + radius * np.cos(a) * np.sin(b),
                    centre[1] + radius * np.sin(a) * np.sin(b),
                    centre[2] + radius * np.cos(b), color=colour, alpha=0.9, linewidth=0)
    ax.plot([], [], "o", color=colour, label=label)   # (surfaces have no legend entry)


def _bodies(ax, sol, case, scale_km: float, lo: np.ndarray, hi: np.ndarray) -> None:
    """The case's bodies to scale where the view reaches them (module docstring)."""
    system = sol.units.get("system")
    units = Units.from_dict(sol.units)
    if system == "earth_moon_cr3bp":
        mu, lu = units.gm, units.lu_km / scale_km
        for name, x, rad, colour in (("Moon", 1 - mu, MOON_RADIUS_KM, "0.55"),
                                     ("Earth", -mu, EARTH_RADIUS_KM, "tab:blue")):
            c = np.array([x * lu, 0.0, 0.0])
            if np.all(c >= lo) and np.all(c <= hi):
                _sphere(ax, c, rad / scale_km, colour, f"{name} (to scale)")
            else:
                gap = np.linalg.norm(c - (lo + hi) / 2) * scale_km
                ax.text2D(0.02, 0.02 + 0.03 * (name == "Moon"),
                          f"{name}: along {'-' if c[0] < lo[0] else '+'}x, {gap:,.0f} km "
                          "from the view's centre (outside it)", transform=ax.transAxes,
                          fontsize=8)
    elif system == "sun_two_body":
        _sphere(ax, np.zeros(3), SUN_RADIUS_KM / scale_km, "gold", "Sun (to scale)")
        gm = units.lu_km ** 3 / units.tu_s ** 2 * units.gm    # km^3/s^2
        if case is not None:
            for name, x, colour in (("departure orbit", case.x0, "tab:blue"),
                                    ("arrival orbit", case.x_target, "tab:red")):
                s = units.cartesian_si(x)[:6] / 1000.0
                o = kepler_orbit(s, gm) / scale_km
                ax.plot(o[:, 0], o[:, 1], o[:, 2], ":", color=colour, lw=1, label=name)
    else:
        _sphere(ax, np.zeros(3), EARTH_RADIUS_KM / scale_km, "tab:blue", "Earth (to scale)")


def plot_mission(sol, path, case=None, u_max_n: float | None = None) -> None:
    """Write the PNG (module docstring). ``case``: the catalogue case (the departure and
    arrival orbits of a Sun-centred transfer); ``u_max_n``: the thrust bound [N]. Raises
    DaddyError without matplotlib or for a system without a frame in space."""
    plt = _pyplot()
    from matplotlib.colors import Normalize

    pos, scale_km, unit = natural_frame(sol)
    earth = is_earth_centred(sol)
    days = node_times_s(sol) / 86400.0
    thrust = np.linalg.norm(sol.thrust_n, axis=1)
    bound = u_max_n if u_max_n else float(np.max(thrust, initial=0.0)) or 1.0
    on = thrust > THRUST_ON * bound

    fig = plt.figure(figsize=(17, 9))
    grid = fig.add_gridspec(1, 2, width_ratios=(1.25, 1))
    ax = fig.add_subplot(grid[0, 0], projection="3d")
    if earth:   # the path coloured by time: revolutions stay apart
        cmap, norm = plt.get_cmap("viridis_r"), Normalize(days[0], days[-1])
        step = max(1, len(pos) // 2000)
        for k in range(0, len(pos) - 1, step):
            seg = pos[k:k + step + 1]
            ax.plot(seg[:, 0], seg[:, 1], seg[:, 2], color=cmap(norm(days[k])), lw=0.5)
        fig.colorbar(plt.cm.ScalarMappable(norm=norm, cmap=cmap), ax=ax, shrink=0.5,
                     pad=0.08, label="time [day]")
    else:
        ax.plot(pos[:, 0], pos[:, 1], pos[:, 2], "-", color="k", lw=1.0, label="trajectory")
    ax.plot(*pos[0], "o", color="tab:green", label="departure")
    ax.plot(*pos[-1], "*", color="tab:red", ms=12, label="arrival")
    lo, hi = pos.min(axis=0), pos.max(axis=0)
    span = float(np.max(hi - lo)) or 1.0
    centre = (lo + hi) / 2
    lo, hi = centre - 0.55 * span, centre + 0.55 * span
    _bodies(ax, sol, case, scale_km, lo, hi)
    u = thrust_in_frame(sol)
    idx = np.flatnonzero(thrust > 0.01 * bound)
    if len(idx):
        idx = idx[np.linspace(0, len(idx) - 1, min(MAX_ARROWS, len(idx))).astype(int)]
        d = u[idx] / bound * 0.12 * span
        ax.quiver(pos[idx, 0], pos[idx, 1], pos[idx, 2], d[:, 0], d[:, 1], d[:, 2],
                  color="tab:orange", lw=1.2, arrow_length_ratio=0.3,
                  label="thrust (length: |u| / u_max)")
    ax.set_xlim(lo[0], hi[0])
    ax.set_ylim(lo[1], hi[1])
    ax.set_zlim(lo[2], hi[2])
    ax.set_box_aspect((1, 1, 1))
    ax.set_xlabel(f"x [{unit}]")
    ax.set_ylabel(f"y [{unit}]")
    ax.set_zlabel(f"z [{unit}]")
    frame = {"earth_moon_cr3bp": "Earth-Moon rotating frame, barycentre",
             "sun_two_body": "ecliptic J2000, Sun-centred"}.get(sol.units.get("system"),
                                                                "EME2000, Earth-centred")
    ax.set_title(f"{sol.case}: {frame}")
    ax.legend(loc="upper left", fontsize=8)

    # thrust and switching structure; an Earth-centred transfer of many revolutions: each
    # revolution's duty cycle (its thrusting time over its time), readable at 1,000+ stages
    rows = 4 if earth else 3
    right = grid[0, 1].subgridspec(rows, 1)
    a1 = fig.add_subplot(right[0])
    x = days
    label = f"thrust arcs (> {THRUST_ON:g} u_max): {switches(on)} switches"
    # (Earth-centred stages are angles: the revolutions made at each node)
    revs = np.concatenate([[0.0], np.cumsum(sol.stage_dt)]) / (2 * np.pi) if earth else None
    if earth and sol.N > DENSE_STAGES:
        rev = np.floor(revs[:-1]).astype(int)
        dt = np.diff(days)
        duty = np.bincount(rev, dt * on) / np.bincount(rev, dt)
        starts = np.interp(np.arange(len(duty)), revs, days)
        a1.step(starts, duty, where="post", color="tab:orange", label=label)
        a1.set_ylim(0, 1.05)
        a1.set_ylabel("duty cycle per revolution")
    else:
        a1.step(x[:-1], thrust, where="post", color="tab:orange")
        a1.fill_between(x[:-1], 0, bound, where=on, step="post", color="tab:orange",
                        alpha=0.15, label=label)
        if u_max_n:
            a1.axhline(u_max_n, color="k", ls="--", lw=0.8, label="u_max")
        a1.set_ylim(0, 1.1 * bound)
        a1.set_ylabel("thrust [N]")
    a1.legend(fontsize=8, loc="lower right")
    # mass
    a2 = fig.add_subplot(right[1], sharex=a1)
    if sol.X_si.shape[1] >= 7:
        m = sol.X_si[:, 6]
        a2.plot(x, m, color="tab:purple", label=f"propellant {m[0] - m[-1]:.3f} kg")
        a2.legend(fontsize=8)
    a2.set_ylabel("mass [kg]")
    a2.ticklabel_format(axis="y", useOffset=False)
    # orbit
    a3 = fig.add_subplot(right[2], sharex=a1)
    if earth:
        el = sol.elements
        a3.plot(x, el[:, 0], color="tab:blue", lw=0.8)
        a3.set_ylabel("a [km]", color="tab:blue")
        a3.ticklabel_format(axis="y", useOffset=False)
        ae = a3.twinx()
        ae.plot(x, el[:, 1], color="tab:green", lw=0.8)
        ae.set_ylabel("e", color="tab:green")
        a4 = fig.add_subplot(right[3], sharex=a1)
        a4.plot(x, el[:, 2], color="tab:red", lw=0.8, label="i")
        raan = np.degrees(np.unwrap(np.radians(el[:, 3])))
        defined = el[:, 2] > RAAN_MIN_INCLINATION_DEG   # (undefined on an equatorial orbit)
        if defined.any():
            a4.plot(x, np.where(defined, raan, np.nan), color="tab:cyan", lw=0.8,
                    label=f"RAAN (where i > {RAAN_MIN_INCLINATION_DEG:g} deg)")
        shown = np.concatenate([el[:, 2], raan[defined]])
        lo_deg, hi_deg = float(shown.min()), float(shown.max())
        if hi_deg - lo_deg < 1.0:   # round-off of a constant angle is not drawn as a change
            mid = (lo_deg + hi_deg) / 2
            a4.set_ylim(mid - 0.5, mid + 0.5)
        a4.ticklabel_format(axis="y", useOffset=False)
        a4.set_ylabel("[deg]")
        a4.legend(fontsize=8)
        top = a1.secondary_xaxis("top", functions=(
            lambda d: np.interp(d, days, revs), lambda r: np.interp(r, revs, days)))
        top.set_xlabel("revolutions")
        a3 = a4
    else:
        dist, label = _nearest_body(sol)
        a3.plot(x, dist, color="tab:blue")
        a3.set_ylabel(label)
    a3.set_xlabel("time [day]")
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def _nearest_body(sol) -> tuple[np.ndarray, str]:
    """((N+1,) distance of each node to the nearest body's centre, its axis label): the Earth
    or the Moon [1000 km] (CR3BP), the Sun [AU]."""
    r = sol.X_si[:, :3] / 1000.0
    units = Units.from_dict(sol.units)
    if sol.units.get("system") != "earth_moon_cr3bp":
        return np.linalg.norm(r, axis=1) / AU_KM, "distance to the Sun [AU]"
    mu = units.gm
    return np.minimum(np.linalg.norm(r - [-mu * units.lu_km, 0, 0], axis=1),
                      np.linalg.norm(r - [(1 - mu) * units.lu_km, 0, 0], axis=1)) / 1000.0, \
        "distance to the Earth or the Moon [1000 km]"
