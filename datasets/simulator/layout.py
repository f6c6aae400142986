"""Harbours drawn per seed: a marina-like layout and its survey route from one generator.

:func:`drawn_world` draws one to three rectangular **basins** joined by **channels** (15-40 m
wide, 50-250 m long; a single basin gets a dead-end channel, its closed mouth) and dresses their
quays with **docks** (notches that split a quay into collinear pieces with gaps), groups of
**finger piers**, floating **pontoons** and **moored hulls** (islands in the water), a
**breakwater** with two faces in the first basin (and maybe in others), **rounded corners** and
**coves** (short curved stretches that no line fits). Every wall gets its own echo strength and
band thickness from its material (:data:`MATERIALS`). The water is one shapely polygon (basins,
channels, docks and coves united; piers, breakwaters and rounded corners taken out; hulls and
pontoons its holes), so every world is a closed harbour by construction.

The route is one closed lap, followed round and round: a racetrack ``lane_m`` inside each
basin's quays (round the breakwater's tip, so both its faces are seen), into every channel on one
lane and back on the other (its walls seen again from the other side), round the basin at its
end and back. A lap of 200-790 m (:data:`LAP_RANGE_M`) takes 7-29 min at 0.45 m/s, so in a
1,800 s run every place is seen again along the same track 5-30 min later. A draw whose route
comes closer than :data:`ROUTE_CLEARANCE_M` to a wall, whose lap is out of range or whose pieces
overlap is thrown away and drawn again from the same generator (so a seed gives one world).

Frames: the basins are built axis-aligned in a layout frame, basin 0 centred on the origin; the
whole world is then rotated by a random angle about the origin (local East-North metres).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt

from sonarslam.datasets.errors import MissingExtraError
from sonarslam.datasets.simulator.path import route_samples
from sonarslam.datasets.simulator.world import World, clearance_m, inside, rotate_points
from sonarslam.features.geometry import FloatArray

# shapely is the 'sim' extra: only the drawn worlds need it, the fixed ones and the rest of the
# simulator import without it (drawn_world names the extra when it is missing)
_SHAPELY_MISSING: ModuleNotFoundError | None = None
try:
    import shapely
    from shapely.geometry import Point, Polygon, box
    from shapely.geometry.base import BaseGeometry
except ModuleNotFoundError as missing:
    _SHAPELY_MISSING = missing

__all__ = [
    "ROUTE_CLEARANCE_M",
    "ROUTE_TURN_RADIUS_M",
    "LAP_RANGE_M",
    "MATERIALS",
    "drawn_world",
]

#: Closest the route comes to any wall (m), checked on every draw.
ROUTE_CLEARANCE_M = 4.0
#: Fillet radius of the route's corners (m).
ROUTE_TURN_RADIUS_M = 2.5
#: Accepted lap lengths (m): 7.4-29 min at 0.45 m/s, so that a 1,800 s run revisits every place.
LAP_RANGE_M = (200.0, 790.0)
#: Mean speed the lap times of ``World.layout`` are given at (m/s; the scenarios' speed).
LAYOUT_SPEED_MPS = 0.45

#: Echo strength (a factor on the echo model's gain) and band thickness (the length of the
#: echo's tail behind the face, m) of each material, drawn uniformly in these ranges: per wall
#: for quays, per structure for the others (a hull is one steel plate).
MATERIALS: dict[str, dict[str, tuple[float, float]]] = {
    "quay": {"gain": (0.7, 1.3), "band_m": (0.15, 0.5)},  # concrete, sheet piling
    "breakwater": {"gain": (0.5, 0.9), "band_m": (0.6, 1.5)},  # rubble mound: weak, thick
    "hull": {"gain": (1.1, 1.6), "band_m": (0.1, 0.25)},  # steel: strong, thin
    "pontoon": {"gain": (0.8, 1.2), "band_m": (0.2, 0.5)},
    "pier": {"gain": (0.7, 1.2), "band_m": (0.2, 0.6)},
}

_MAX_DRAWS = 500
_FACET_M = 0.75  # facet length of curved walls (m)
_CORNER_KEEP_M = 12.0  # no quay feature this close to a basin corner (m)
_MOUTH_KEEP_M = 11.0  # ... nor to a channel mouth (m)

# Sides of a basin: 0 south, 1 east, 2 north, 3 west. Along side k the lap travels _D[k] (the
# basin's racetrack runs counter-clockwise) and the quay's outward normal (into the land) is
# _N[k], the right of _D[k]. A point of side k is (u along it from its start corner, v inside).
_D = np.array([[1.0, 0.0], [0.0, 1.0], [-1.0, 0.0], [0.0, -1.0]])
_N = np.array([[0.0, -1.0], [1.0, 0.0], [0.0, 1.0], [-1.0, 0.0]])


class _Reject(Exception):
    """This draw cannot be completed: draw again."""


@dataclass
class _Channel:
    side: int  # side of the parent basin it leaves from
    u_m: float  # its centre along that side
    width_m: float
    length_m: float
    child: _Basin | None  # the basin at its end; None: a dead end


@dataclass
class _Basin:
    x0: float
    y0: float
    x1: float
    y1: float
    entry: _Channel | None = None  # the channel from the parent (None: the first basin)
    entry_u_m: float = 0.0  # the entry channel's centre along this basin's entry side
    breakwater: tuple[int, float, float, float, float] | None = None  # side, u, thick, long, gap
    channels: list[_Channel] = field(default_factory=list)
    used: dict[int, list[tuple[float, float]]] = field(default_factory=dict)

    @property
    def entry_side(self) -> int | None:
        return None if self.entry is None else (self.entry.side + 2) % 4

    def length(self, side: int) -> float:
        return self.x1 - self.x0 if side % 2 == 0 else self.y1 - self.y0

    def depth(self, side: int) -> float:
        return self.length(side + 1)

    def corner(self, side: int) -> FloatArray:
        """The start corner of ``side`` (in the racetrack's direction)."""
        c = [[self.x0, self.y0], [self.x1, self.y0], [self.x1, self.y1], [self.x0, self.y1]]
        return np.array(c[side % 4], dtype=np.float64)

    def at(self, side: int, u_m: float, v_m: float) -> FloatArray:
        """The point ``u_m`` along ``side`` and ``v_m`` inside its quay (negative: outside)."""
        return self.corner(side) + u_m * _D[side % 4] - v_m * _N[side % 4]

    def rect(self) -> Polygon:
        return box(self.x0, self.y0, self.x1, self.y1)

    def free(self, side: int, lo: float, hi: float) -> bool:
        if lo < 0.0 or hi > self.length(side):
            return False
        return all(hi <= a or lo >= b for a, b in self.used.get(side % 4, []))

    def reserve(self, side: int, lo: float, hi: float) -> None:
        self.used.setdefault(side % 4, []).append((lo, hi))


@dataclass
class _Draw:
    """One draw in progress: its generator, the pieces of water and land, what was placed."""

    rng: np.random.Generator
    lane_m: float
    basins: list[_Basin] = field(default_factory=list)
    water: list[BaseGeometry] = field(default_factory=list)
    land: list[BaseGeometry] = field(default_factory=list)
    holes: list[Polygon] = field(default_factory=list)
    structures: list[tuple[Polygon, str]] = field(default_factory=list)
    arcs: list[tuple[FloatArray, float]] = field(default_factory=list)  # centre, radius (m)
    counts: dict[str, int] = field(default_factory=dict)
    footprints: list[tuple[Polygon, int]] = field(default_factory=list)  # shape, basin index

    def u(self, lo: float, hi: float) -> float:
        return float(self.rng.uniform(lo, hi))

    def count(self, name: str) -> None:
        self.counts[name] = self.counts.get(name, 0) + 1


def _disc(centre: FloatArray, radius_m: float) -> Polygon:
    quad = max(int(math.ceil(radius_m * math.pi / 2.0 / _FACET_M)), 3)
    disc: Polygon = Point(float(centre[0]), float(centre[1])).buffer(radius_m, quad_segs=quad)
    return disc


def _quad(b: _Basin, side: int, u0: float, u1: float, v0: float, v1: float) -> Polygon:
    """The rectangle ``[u0, u1] x [v0, v1]`` in the frame of ``side``."""
    return _poly(b, side, [(u0, v0), (u1, v0), (u1, v1), (u0, v1)])


def _poly(b: _Basin, side: int, uv: list[tuple[float, float]]) -> Polygon:
    poly: Polygon = Polygon([b.at(side, u, v) for u, v in uv]).normalize()
    return poly


def _lane_sep_m(width_m: float) -> float:
    """Distance between a channel's two lanes (m): a third of its width, room for a U-turn."""
    return max(2.0 * ROUTE_TURN_RADIUS_M + 1.5, width_m / 3.0)


def _detour_room_m(lane_m: float, width_m: float) -> float:
    """How far a channel's centre must be from a basin's corners (m)."""
    turns = lane_m + _lane_sep_m(width_m) / 2.0 + 2.0 * ROUTE_TURN_RADIUS_M + 1.0
    return max(turns, width_m / 2.0 + _MOUTH_KEEP_M)


# -- basins, channels, breakwaters --------------------------------------------------------------


def _new_basin(d: _Draw, b: _Basin) -> None:
    """Register a basin: its water, its footprint, and maybe rounded corners."""
    d.basins.append(b)
    d.water.append(b.rect())
    d.footprints.append((b.rect(), len(d.basins) - 1))
    for side in range(4):
        b.reserve(side, 0.0, _CORNER_KEEP_M)
        b.reserve(side, b.length(side) - _CORNER_KEEP_M, b.length(side))
        if d.rng.random() < 0.4:  # the corner at the start of this side, rounded
            r = d.u(4.0, 10.0)
            square = _quad(b, side, 0.0, r, 0.0, r)
            centre = b.at(side, r, r)
            d.land.append(square.difference(_disc(centre, r)))
            d.arcs.append((centre, r))
            d.count("rounded_corners")


def _add_breakwater(d: _Draw, b: _Basin, side: int) -> bool:
    """A breakwater from ``side``'s quay, 4-7 m thick, reaching 40-62 % across the basin."""
    lane, gap = d.lane_m, d.u(8.0, 12.0)
    thick = d.u(4.0, 7.0)
    room = lane + gap + 2.0 * ROUTE_TURN_RADIUS_M + 1.5
    lo, hi = room, b.length(side) - room - thick
    depth = b.depth(side)
    long_m = min(d.u(0.40, 0.62) * depth, depth - gap - lane - 1.0)
    if hi <= lo or long_m < 0.3 * depth or side == b.entry_side:
        return False
    u = d.u(lo, hi)
    if not b.free(side, u - 4.0, u + thick + 4.0):
        return False
    b.breakwater = (side, u, thick, long_m, gap)
    b.reserve(side, u - 4.0, u + thick + 4.0)
    piece = _quad(b, side, u, u + thick, -1.0, long_m)
    d.land.append(piece)
    d.structures.append((piece, "breakwater"))
    d.count("breakwaters")
    return True


def _mouth_fillets(d: _Draw, b: _Basin, side: int, u_m: float, width_m: float) -> None:
    """Maybe round the two land corners where a channel meets a quay (3-8 m)."""
    for edge, sign in ((u_m - width_m / 2.0, -1.0), (u_m + width_m / 2.0, 1.0)):
        if d.rng.random() < 0.5:
            r = d.u(3.0, 8.0)
            a, c = sorted((edge, edge + sign * r))
            centre = b.at(side, edge + sign * r, -r)
            d.water.append(_quad(b, side, a, c, -r, 0.0).difference(_disc(centre, r)))
            d.arcs.append((centre, r))
            d.count("rounded_corners")


def _add_channel(
    d: _Draw,
    parent: _Basin,
    length_range_m: tuple[float, float],
    child: bool,
    scale: float = 1.0,
) -> bool:
    """A channel from a free side of ``parent``, to a new basin (its sides up to ``scale`` times
    110 m x 90 m) or (``child`` False) a dead end."""
    sides = [s for s in range(4) if s != parent.entry_side]
    if parent.breakwater is not None:
        sides.remove(parent.breakwater[0])
    if not sides:
        return False
    side = int(d.rng.choice(sides))
    width = d.u(15.0, 40.0)
    length = d.u(*length_range_m)
    room = _detour_room_m(d.lane_m, width)
    if parent.length(side) <= 2.0 * room:
        return False
    u = d.u(room, parent.length(side) - room)
    keep = width / 2.0 + _MOUTH_KEEP_M
    if not parent.free(side, u - keep, u + keep):
        return False
    ch = _Channel(side, u, width, length, None)
    core = _quad(parent, side, u - width / 2.0, u + width / 2.0, -length + 1.0, -1.0)
    others = [f for f, k in d.footprints if d.basins[k] is not parent]
    if any(core.buffer(10.0).intersects(f) for f in others):
        return False
    new: _Basin | None = None
    if child:
        along, across = d.u(50.0, 110.0 * scale), d.u(40.0, 90.0 * scale)
        room_c = _detour_room_m(d.lane_m, width)
        if along <= 2.0 * room_c:
            return False
        u_c = d.u(room_c, along - room_c)  # the channel's centre along the child's entry side
        q = parent.at(side, u, -length)  # ... at the child's quay
        start = q + u_c * _D[side]  # the child's entry side runs against the parent's side
        pts = np.array([start, start - along * _D[side]])
        pts = np.vstack([pts, pts + across * _N[side]])
        (x0, y0), (x1, y1) = pts.min(axis=0), pts.max(axis=0)
        new = _Basin(float(x0), float(y0), float(x1), float(y1), entry=ch)
        if any(new.rect().buffer(15.0).intersects(f) for f, _ in d.footprints):
            return False
        entry = (side + 2) % 4
        new.entry_u_m = float(np.dot(q - new.corner(entry), _D[entry]))
        ch.child = new
    parent.reserve(side, u - keep, u + keep)
    parent.channels.append(ch)
    chan = _quad(parent, side, u - width / 2.0, u + width / 2.0, -length - 1.0, 1.0)
    d.water.append(chan)
    d.footprints.append((chan, d.basins.index(parent)))
    _mouth_fillets(d, parent, side, u, width)
    d.count("channels")
    if new is not None:
        _new_basin(d, new)
        entry = (side + 2) % 4
        new.reserve(entry, new.entry_u_m - keep, new.entry_u_m + keep)
        _mouth_fillets(d, new, entry, new.entry_u_m, width)
    return True


# -- quay features ------------------------------------------------------------------------------


def _slot(d: _Draw, b: _Basin, side: int, span_m: float) -> float | None:
    """A free start ``u`` for a feature of ``span_m`` along ``side`` (reserved), or None."""
    for _ in range(8):
        lo = d.u(0.0, max(b.length(side) - span_m, 0.0))
        if b.free(side, lo - 3.0, lo + span_m + 3.0):
            b.reserve(side, lo - 3.0, lo + span_m + 3.0)
            return lo
    return None


def _add_feature(d: _Draw, b: _Basin, side: int, kind: str) -> bool:
    lane = d.lane_m
    reach = lane - ROUTE_CLEARANCE_M - 0.5  # how far into the water a feature may reach (m)
    if kind == "dock":  # a notch into the land: the quay goes on collinear beyond it
        width, deep = d.u(8.0, 20.0), d.u(6.0, 15.0)
        u = _slot(d, b, side, width)
        if u is None:
            return False
        notch = _quad(b, side, u, u + width, -deep, 0.5)
        own = d.basins.index(b)
        if any(notch.buffer(6.0).intersects(f) for f, k in d.footprints if k != own):
            return False
        d.water.append(notch)
    elif kind == "piers":  # a group of finger piers
        n, width, step = int(d.rng.integers(2, 6)), d.u(1.5, 3.0), d.u(8.0, 16.0)
        u = _slot(d, b, side, (n - 1) * step + width)
        if u is None:
            return False
        for i in range(n):
            long_m = d.u(5.0, reach)
            pier = _quad(b, side, u + i * step, u + i * step + width, -1.0, long_m)
            d.land.append(pier)
            d.structures.append((pier, "pier"))
    elif kind == "pontoon":  # a float moored off the quay
        long_m, off, width = d.u(12.0, 30.0), d.u(3.0, 5.0), d.u(2.5, 4.0)
        u = _slot(d, b, side, long_m)
        if u is None:
            return False
        piece = _quad(b, side, u, u + long_m, off, off + width)
        d.holes.append(piece)
        d.structures.append((piece, "pontoon"))
    elif kind == "hull":  # a moored vessel, bow at either end
        long_m, off, beam = d.u(15.0, 30.0), d.u(1.5, 3.0), d.u(4.0, 6.0)
        bow = d.u(0.8, 1.5) * beam
        u = _slot(d, b, side, long_m)
        if u is None:
            return False
        uv = [
            (0.0, 0.0),
            (long_m - bow, 0.0),
            (long_m, beam / 2.0),
            (long_m - bow, beam),
            (0, beam),
        ]
        flip = d.rng.random() < 0.5
        hull = _poly(b, side, [(u + (long_m - x if flip else x), off + y) for x, y in uv])
        d.holes.append(hull)
        d.structures.append((hull, "hull"))
    elif kind == "cove":  # a short curved stretch of quay
        chord, sag = d.u(12.0, 24.0), d.u(2.0, 5.0)
        u = _slot(d, b, side, chord)
        if u is None:
            return False
        radius = (chord * chord / 4.0 + sag * sag) / (2.0 * sag)
        centre = b.at(side, u + chord / 2.0, radius - sag)
        strip = _quad(b, side, u - 1.0, u + chord + 1.0, -sag - 1.0, 0.0)
        d.water.append(strip.intersection(_disc(centre, radius)))
        d.arcs.append((centre, radius))
    else:
        raise ValueError(f"unknown quay feature {kind!r}")
    d.count(kind if kind.endswith("s") else kind + "s")
    return True


# -- the route ----------------------------------------------------------------------------------


def _side_inserts(d: _Draw, b: _Basin) -> dict[int, list[tuple[float, list[FloatArray]]]]:
    """Per side, the detours off its racetrack edge: ``(u, waypoints)``."""
    lane = d.lane_m
    out: dict[int, list[tuple[float, list[FloatArray]]]] = {k: [] for k in range(4)}
    if b.breakwater is not None:  # round the tip: along one face, back along the other
        side, u, thick, long_m, gap = b.breakwater
        pts = [
            b.at(side, u - gap, lane),
            b.at(side, u - gap, long_m + gap),
            b.at(side, u + thick + gap, long_m + gap),
            b.at(side, u + thick + gap, lane),
        ]
        out[side].append((u, pts))
    for ch in b.channels:
        sep = _lane_sep_m(ch.width_m)
        p_in, p_out = (
            b.at(ch.side, ch.u_m - sep / 2.0, lane),
            b.at(ch.side, ch.u_m + sep / 2.0, lane),
        )
        if ch.child is None:  # to the dead end and back on the other lane
            far = ch.length_m - max((ch.width_m - sep) / 2.0, 6.0)
            mid = [b.at(ch.side, ch.u_m - sep / 2.0, -far), b.at(ch.side, ch.u_m + sep / 2.0, -far)]
        else:
            mid = _waypoints(d, ch.child)
        out[ch.side].append((ch.u_m, [p_in, *mid, p_out]))
    return out


def _waypoints(d: _Draw, b: _Basin) -> list[FloatArray]:
    """The racetrack of ``b`` with its detours: from its first corner (the first basin) or from
    its entry channel's inbound lane round to its outbound lane (a basin at a channel's end)."""
    lane = d.lane_m
    inserts = _side_inserts(d, b)
    first = 0 if b.entry is None else (b.entry.side + 2) % 4
    pts: list[FloatArray] = []
    if b.entry is not None:
        sep = _lane_sep_m(b.entry.width_m)
        pts.append(b.at(first, b.entry_u_m + sep / 2.0, lane))
    for k in range(first + (b.entry is not None), first + 4 + (b.entry is not None)):
        side = k % 4
        pts.append(b.at(side, lane, lane))
        if b.entry is not None and side == first:
            break
        for _, detour in sorted(inserts[side], key=lambda x: x[0]):
            pts.extend(detour)
    if b.entry is not None:
        pts.append(b.at(first, b.entry_u_m - _lane_sep_m(b.entry.width_m) / 2.0, lane))
    return pts


# -- walls and materials ------------------------------------------------------------------------


def _rings(water: Polygon) -> list[FloatArray]:
    rings = [np.asarray(water.exterior.coords)[:-1]]
    rings += [np.asarray(r.coords)[:-1] for r in water.interiors]
    return rings


def _materials(
    d: _Draw, walls_m: FloatArray
) -> tuple[list[str], npt.NDArray[np.int64], FloatArray, FloatArray]:
    """Per wall: material, curve index (-1: straight), echo gain factor, band thickness (m)."""
    n = walls_m.shape[0]
    material = ["quay"] * n
    curve = np.full(n, -1, dtype=np.int64)
    ends = walls_m.reshape(-1, 2)
    for k, (centre, r) in enumerate(d.arcs):
        dist = np.abs(np.linalg.norm(ends - centre, axis=1) - r).reshape(n, 2)
        short = np.linalg.norm(walls_m[:, 1] - walls_m[:, 0], axis=1) < 2.5 * _FACET_M
        curve[(dist.max(axis=1) < 0.02) & short & (curve < 0)] = k
    structure = np.full(n, -1, dtype=np.int64)
    mids = shapely.points(walls_m.mean(axis=1))
    for j, (poly, _) in enumerate(d.structures):
        on = shapely.distance(poly.exterior, mids) < 1e-6
        structure[on & (structure < 0)] = j
    gain, band = np.empty(n), np.empty(n)
    drawn: dict[tuple[str, int], tuple[float, float]] = {}
    for i in range(n):
        if curve[i] >= 0:
            key = ("curve", int(curve[i]))
            material[i] = "quay"
        elif structure[i] >= 0:
            material[i] = d.structures[structure[i]][1]
            key = ("structure", int(structure[i]))
        else:
            key = ("wall", i)
        if key not in drawn:
            m = MATERIALS[material[i]]
            drawn[key] = (d.u(*m["gain"]), d.u(*m["band_m"]))
        gain[i], band[i] = drawn[key]
    return material, curve, gain, band


# -- the world ----------------------------------------------------------------------------------


def _draw_once(rng: np.random.Generator, n_basins: int) -> World:
    # three basins in one lap of at most 790 m are smaller ones, on shorter channels
    scale = 0.7 if n_basins == 3 else 1.0
    d = _Draw(rng=rng, lane_m=float(rng.uniform(13.0, 18.0 if n_basins < 3 else 15.0)))
    w, h = d.u(60.0, 120.0 * scale), d.u(60.0, 100.0 * scale)
    first = _Basin(-w / 2.0, -h / 2.0, w / 2.0, h / 2.0)
    _new_basin(d, first)
    if not _add_breakwater(d, first, int(rng.integers(4))):
        raise _Reject("no room for the breakwater")
    lengths = {1: (50.0, 250.0), 2: (50.0, 250.0), 3: (50.0, 80.0)}[n_basins]
    tries = 0
    while len(d.basins) < n_basins:
        tries += 1
        if tries > 30:
            raise _Reject("no room for the basins")
        parent = d.basins[int(rng.integers(len(d.basins)))]
        if _add_channel(d, parent, lengths, child=True, scale=scale):
            new = d.basins[-1]
            if rng.random() < 0.4:
                _add_breakwater(d, new, int(rng.integers(4)))
    if n_basins == 1 and not any(_add_channel(d, first, lengths, False) for _ in range(30)):
        raise _Reject("no room for the channel")
    wanted = ["dock", "piers", "pontoon", "hull", "cove"]
    kinds = ["dock", "piers", "pontoon", "hull", "cove"]
    wanted += [str(k) for k in rng.choice(kinds, int(rng.integers(2, 7)))]
    for i, kind in enumerate(wanted):
        placed = False
        for _ in range(30):
            b = d.basins[int(rng.integers(len(d.basins)))]
            if _add_feature(d, b, int(rng.integers(4)), kind):
                placed = True
                break
        if not placed and i < len(kinds):
            raise _Reject(f"no room for a {kind}")
    water = shapely.union_all(d.water).difference(shapely.union_all(d.land))
    if d.holes:
        water = water.difference(shapely.union_all(d.holes))
    water = shapely.remove_repeated_points(shapely.simplify(water, 1e-6), 1e-3)
    if not isinstance(water, Polygon) or not water.is_valid:
        raise _Reject("the water is not one polygon")
    if len(water.interiors) != len(d.holes):
        raise _Reject("an island touches a quay")
    walls = np.concatenate([np.stack([r, np.roll(r, -1, axis=0)], axis=1) for r in _rings(water)])
    route = np.array(_waypoints(d, first))
    material, curve, gain, band = _materials(d, walls)
    world = World(name="drawn", walls_m=walls, route_m=route)
    try:
        samples, lap_m = route_samples(route, ROUTE_TURN_RADIUS_M, 0.5)
    except ValueError as exc:  # a leg too short for its fillets
        raise _Reject(str(exc)) from exc
    if not LAP_RANGE_M[0] <= lap_m <= LAP_RANGE_M[1]:
        raise _Reject(f"lap of {lap_m:.0f} m")
    if not inside(world, samples).all():
        raise _Reject("the route leaves the water")
    closest = float(clearance_m(world, samples).min())
    if closest < ROUTE_CLEARANCE_M:
        raise _Reject(f"the route comes {closest:.1f} m from a wall")
    rotation = float(rng.uniform(-math.pi, math.pi))
    layout: dict[str, Any] = {
        "basins": [[round(b.x1 - b.x0, 1), round(b.y1 - b.y0, 1)] for b in d.basins],
        "channels": [
            [round(ch.width_m, 1), round(ch.length_m, 1), ch.child is None]
            for b in d.basins
            for ch in b.channels
        ],
        "lane_m": round(d.lane_m, 2),
        "lap_m": round(lap_m, 1),
        "lap_s": round(lap_m / LAYOUT_SPEED_MPS, 1),
        "route_clearance_m": round(closest, 2),
        "rotation_deg": round(math.degrees(rotation), 2),
        "walls": int(walls.shape[0]),
        "curved_walls": int(np.count_nonzero(curve >= 0)),
        **{
            k: d.counts.get(k, 0)
            for k in (
                "breakwaters",
                "docks",
                "piers",
                "pontoons",
                "hulls",
                "coves",
                "rounded_corners",
            )
        },  # fmt: skip
    }
    return World(
        name="drawn",
        walls_m=rotate_points(walls, rotation),
        route_m=rotate_points(route, rotation),
        route_turn_radius_m=ROUTE_TURN_RADIUS_M,
        wall_gain=gain,
        wall_band_m=band,
        wall_curve=curve,
        wall_material=tuple(material),
        layout=layout,
    )


def drawn_world(rng: np.random.Generator) -> World:
    """A marina-like harbour and its survey route, drawn from ``rng`` (module docstring).

    Parameters
    ----------
    rng : numpy.random.Generator
        The only source of randomness: draws that fail a check are drawn again from it.

    Returns
    -------
    World
        Walls (closed loops: the outline and one per hull or pontoon) with their echo gain,
        band thickness, material and curve index; the closed route (turn radius
        :data:`ROUTE_TURN_RADIUS_M`, at least :data:`ROUTE_CLEARANCE_M` from every wall); and
        ``layout``, a summary of what was drawn (basins, channels, features, lap).

    Raises
    ------
    RuntimeError
        If no valid world comes out of :data:`_MAX_DRAWS` draws (never seen).
    MissingExtraError
        If shapely (the ``sim`` extra) is not installed.
    """
    if _SHAPELY_MISSING is not None:
        raise MissingExtraError("sim", "a drawn world", _SHAPELY_MISSING)
    n_basins = int(rng.choice([1, 2, 3], p=[0.3, 0.4, 0.3]))  # drawn once: no bias to the easy
    reasons: dict[str, int] = {}
    for _ in range(_MAX_DRAWS):
        try:
            return _draw_once(rng, n_basins)
        except _Reject as why:
            key = str(why).split(" of ")[0]
            reasons[key] = reasons.get(key, 0) + 1
    raise RuntimeError(f"no valid drawn world in {_MAX_DRAWS} draws: {reasons}")
