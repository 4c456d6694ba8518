"""A building's bent magnetic field: the steel along a corridor as magnetic dipoles (issue #27).

Indoors the Earth's field is bent by the building's steel: reinforcing bars and embedded steel in the floor and
ceiling slabs, and steel columns in the walls.  Steel in the Earth's field is magnetised -- an induced part along
the field (for a column, along its length: its shape makes it magnetise along its axis) and a remanent part of
any direction left by fabrication and handling -- so each piece is a magnetic dipole, and the field at the phone is
the Earth's plus the sum of the dipoles' fields (the field of a point dipole ``m`` at offset ``r``)::

    B(r) = mu0 / (4 pi) (3 (m . r_hat) r_hat - m) / |r|^3,    mu0 / (4 pi) = 0.1 uT m^3 / (A m^2)

A column is a vertical stack of dipoles from the floor to the ceiling (a magnetised rod: its field is that of
poles at its ends).  The disturbance is a function of the phone's *position*, fixed in the building: a walker
standing still sees a constant one, one passing the same place twice sees it twice, and its correlation length
along the walk is the distance to the steel (about 1-2 m) -- nothing here is the attitude filter's Gauss-Markov
model of the field's heading offset (a process in time).

Magnitudes (:func:`corridor_steel`'s defaults).  A 1 m length of 16 mm rebar is 2e-4 m^3 of steel; a storey of
a steel column (an HEB 200, 78 cm^2) 0.023 m^3.  Structural steel carries a magnetisation of the order of
1e3-1e4 A/m (induced in 50 uT plus remanent), so rebar and embedded steel around one point of a slab give moments
of some A m^2 to tens of A m^2, a column tens to a few hundred, a building core (a lift shaft, a steel stair:
tonnes of steel) thousands.  With the defaults (slab steel every 1.5 m along the corridor, isotropic moments of
50 A m^2 sd, in the floor 1.4 m below a hand-held phone and in the ceiling 1.7 m above it; a column in each wall
every 6 m, 100 A m^2 along its axis and 40 A m^2 sd remanent; ceiling beams between them; a core every 20 m,
4-10 m to one side, 2000 A m^2) the field's azimuth at the phone is turned by 6.3-8.2 deg rms per walk (20 uT of
horizontal field; the square walk of the tests, 24 seeds), its autocorrelation along the walk halving in 0.9-1.6
m; the strength varies by 2.5-4.1 uT sd and the dip by about 3 deg, as in buildings, mostly within the attitude
filter's gates.  The real IPIN walks show heading errors of the same size (about 10 deg per segment) but
correlated over several segments: this steel has no disturbance that long (see benchmarks/RESULTS.md, "bent
field").
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

#: mu0 / (4 pi) in uT m^3 per A m^2 (1e-7 T m / A)
MU0_4PI_UT = 0.1
#: dipoles are never nearer the phone than this (m): the point-dipole formula is for a distance large against
#: the piece of steel (a phone against a pillar is not this model's case)
_MIN_DISTANCE_M = 0.3


def dipole_field(points_enu_m, positions_enu_m, moments_enu_A_m2, *, chunk: int = 4096) -> np.ndarray:
    """The summed field (n, 3) in uT of the point dipoles (k, 3) with moments (k, 3) A m^2 at the points (n, 3) m."""
    p = np.atleast_2d(np.asarray(points_enu_m, float))
    pos = np.asarray(positions_enu_m, float).reshape(-1, 3)
    mom = np.asarray(moments_enu_A_m2, float).reshape(-1, 3)
    out = np.zeros((len(p), 3))
    if not len(pos):
        return out
    for i in range(0, len(p), chunk):
        r = p[i:i + chunk, None, :] - pos[None, :, :]  # (c, k, 3)
        d = np.maximum(np.linalg.norm(r, axis=2), _MIN_DISTANCE_M)
        u = r / d[..., None]
        mu = np.einsum("ckj,kj->ck", u, mom)
        out[i:i + chunk] = MU0_4PI_UT * np.einsum("ck,ckj->cj", 1.0 / d ** 3, 3.0 * mu[..., None] * u - mom[None])
    return out


@dataclass(frozen=True)
class SteelField:
    """Magnetised steel as point dipoles: positions (k, 3) in ENU (m, up from the floor) and moments (k, 3) A m^2.

    ``params`` says how they were made (what a recording's metadata keeps instead of every dipole).
    """

    positions_enu_m: np.ndarray
    moments_enu_A_m2: np.ndarray
    params: dict = field(default_factory=dict)

    def __post_init__(self):
        pos = np.array(self.positions_enu_m, float).reshape(-1, 3)
        mom = np.array(self.moments_enu_A_m2, float).reshape(-1, 3)
        if len(pos) != len(mom) or not (np.all(np.isfinite(pos)) and np.all(np.isfinite(mom))):
            raise ValueError("SteelField needs as many finite positions (k, 3) as moments (k, 3)")
        pos.flags.writeable = False
        mom.flags.writeable = False
        object.__setattr__(self, "positions_enu_m", pos)
        object.__setattr__(self, "moments_enu_A_m2", mom)

    def field_at(self, points_enu_m) -> np.ndarray:
        """The *added* field (n, 3) ENU (uT) at the points (n, 3) (ENU m, up from the floor)."""
        return dipole_field(points_enu_m, self.positions_enu_m, self.moments_enu_A_m2)

    def as_dict(self) -> dict:
        return {"kind": "steel dipoles", "n_dipoles": len(self.positions_enu_m), **self.params}


def _along(waypoints_en_m, spacing_m: float, rng: np.random.Generator, jitter: float):
    """Points every ``spacing_m`` (+- ``jitter`` of it) along the polyline: (east, north) and the unit tangent."""
    w = np.asarray(waypoints_en_m, float).reshape(-1, 2)
    seg = np.diff(w, axis=0)
    length = np.hypot(seg[:, 0], seg[:, 1])
    keep = length > 1e-9
    w0, seg, length = w[:-1][keep], seg[keep], length[keep]
    cum = np.r_[0.0, np.cumsum(length)]
    n = int(cum[-1] / spacing_m) + 1
    s = (np.arange(n) + 0.5 + rng.uniform(-jitter, jitter, n)) * spacing_m
    s = s[(s >= 0.0) & (s <= cum[-1])]
    j = np.clip(np.searchsorted(cum, s, side="right") - 1, 0, len(length) - 1)
    tangent = seg[j] / length[j, None]
    return w0[j] + tangent * (s - cum[j])[:, None], tangent


def _distance_to_polyline(points_en_m, waypoints_en_m) -> np.ndarray:
    """Horizontal distance (n,) of the points (n, 2) to the polyline (m)."""
    p = np.asarray(points_en_m, float).reshape(-1, 2)
    w = np.asarray(waypoints_en_m, float).reshape(-1, 2)
    a, b = w[:-1], w[1:]
    ab = b - a
    L2 = np.maximum(np.sum(ab * ab, axis=1), 1e-18)
    u = np.clip(np.einsum("nkj,kj->nk", p[:, None, :] - a[None], ab) / L2, 0.0, 1.0)
    closest = a[None] + u[..., None] * ab[None]
    return np.min(np.linalg.norm(p[:, None, :] - closest, axis=2), axis=1)


def corridor_steel(waypoints_en_m, *, seed: int, earth_field_enu_uT=(0.0, 20.0, -44.0), half_width_m: float = 1.2,
                   storey_m: float = 3.0, slab_spacing_m: float = 1.5, slab_moment_sd_A_m2: float = 50.0,
                   column_spacing_m: float = 6.0, column_moment_A_m2: float = 100.0,
                   column_remanent_sd_A_m2: float = 40.0, column_pieces: int = 6,
                   beam_moment_A_m2: float = 150.0, beam_remanent_sd_A_m2: float = 60.0,
                   core_spacing_m: float = 20.0, core_distance_m: tuple = (4.0, 10.0),
                   core_moment_A_m2: float = 2000.0, core_remanent_sd_A_m2: float = 1000.0) -> SteelField:
    """The steel of a corridor ``2 half_width_m`` wide and ``storey_m`` high along the walk's polyline.

    Slab steel (rebar, conduits, embedded plates) every ``slab_spacing_m`` (+-40 %) in the floor (0.1 m below it)
    and in the ceiling (0.1 m above ``storey_m``), at a uniform place across the corridor, each an isotropic
    Gaussian moment of ``slab_moment_sd_A_m2`` per axis; a column in each wall (0.3 m behind it) every
    ``column_spacing_m`` (+-20 %), ``column_pieces`` dipoles from floor to ceiling that together carry
    ``column_moment_A_m2`` (times 0.5-1.5) along the Earth's vertical field plus a remanent isotropic Gaussian of
    ``column_remanent_sd_A_m2`` per axis; a beam across the ceiling (0.2 m above it) from column to column,
    ``column_pieces`` dipoles that together carry ``beam_moment_A_m2`` (times -1.5..1.5: induced by the horizontal
    field along it, either way) along its axis plus ``beam_remanent_sd_A_m2`` per axis.  Give the corridor once: a polyline that comes back along itself gets
    its steel twice (for a loop walked twice, pass one lap).  Seeded: the same arguments give
    the same building.
    """
    rng = np.random.default_rng([int(seed), 27])
    pos, mom, clear = [], [], []  # clear: how far from every leg (horizontally) a source must stand (m)
    for z in (-0.1, storey_m + 0.1):
        p, t = _along(waypoints_en_m, slab_spacing_m, rng, 0.4)
        normal = np.stack([-t[:, 1], t[:, 0]], axis=1)
        p = p + normal * rng.uniform(-half_width_m, half_width_m, len(p))[:, None]
        pos.append(np.column_stack([p, np.full(len(p), z)]))
        clear.append(np.zeros(len(p)))
        mom.append(rng.standard_normal((len(p), 3)) * slab_moment_sd_A_m2)
    p, t = _along(waypoints_en_m, column_spacing_m, rng, 0.2)
    normal = np.stack([-t[:, 1], t[:, 0]], axis=1)
    down = -1.0 if float(np.asarray(earth_field_enu_uT, float)[2]) < 0 else 1.0  # induced along the vertical field
    for side in (-1.0, 1.0):
        base = p + side * (half_width_m + 0.3) * normal
        m = np.zeros((len(p), 3))
        m[:, 2] = down * column_moment_A_m2 * rng.uniform(0.5, 1.5, len(p))
        m += rng.standard_normal((len(p), 3)) * column_remanent_sd_A_m2
        for k in range(column_pieces):
            z = (k + 0.5) * storey_m / column_pieces
            pos.append(np.column_stack([base, np.full(len(p), z)]))
            clear.append(np.full(len(p), half_width_m))
            mom.append(m / column_pieces)
    span = (half_width_m + 0.3) * ((np.arange(column_pieces) + 0.5) * 2.0 / column_pieces - 1.0)
    m = normal * (beam_moment_A_m2 * rng.uniform(-1.5, 1.5, len(p)))[:, None]
    m = np.column_stack([m, np.zeros(len(p))]) + rng.standard_normal((len(p), 3)) * beam_remanent_sd_A_m2
    for x in span:
        pos.append(np.column_stack([p + x * normal, np.full(len(p), storey_m + 0.2)]))
        clear.append(np.zeros(len(p)))
        mom.append(m / column_pieces)
    p, t = _along(waypoints_en_m, core_spacing_m, rng, 0.3)
    normal = np.stack([-t[:, 1], t[:, 0]], axis=1)
    side = rng.choice((-1.0, 1.0), len(p)) * rng.uniform(*core_distance_m, len(p))
    pos.append(np.column_stack([p + side[:, None] * normal, np.full(len(p), storey_m / 2)]))
    clear.append(np.full(len(p), core_distance_m[0]))
    m = rng.standard_normal((len(p), 3)) * core_remanent_sd_A_m2
    m[:, 2] += down * core_moment_A_m2 * rng.uniform(0.5, 1.5, len(p))
    mom.append(m)
    # a core or a column placed beside one leg may stand on another (a corner, a loop's other side): drop it
    pos, mom, clear = np.concatenate(pos), np.concatenate(mom), np.concatenate(clear)
    keep = _distance_to_polyline(pos[:, :2], waypoints_en_m) >= clear - 1e-9
    pos, mom = pos[keep], mom[keep]
    params = dict(seed=int(seed), half_width_m=half_width_m, storey_m=storey_m, slab_spacing_m=slab_spacing_m,
                  slab_moment_sd_A_m2=slab_moment_sd_A_m2, column_spacing_m=column_spacing_m,
                  column_moment_A_m2=column_moment_A_m2, column_remanent_sd_A_m2=column_remanent_sd_A_m2,
                  column_pieces=column_pieces, beam_moment_A_m2=beam_moment_A_m2,
                  beam_remanent_sd_A_m2=beam_remanent_sd_A_m2, core_spacing_m=core_spacing_m,
                  core_distance_m=list(core_distance_m), core_moment_A_m2=core_moment_A_m2,
                  core_remanent_sd_A_m2=core_remanent_sd_A_m2)
    return SteelField(pos, mom, params)
