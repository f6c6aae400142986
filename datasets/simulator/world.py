"""Simulated worlds: the walls an MSIS sees, as straight segments in local East-North metres.

Every world is made of closed loops of segments (the harbour outline, a pier, a moored hull), so
that "inside the water" is decided by crossing parity (:func:`inside`). The world frame is local
East-North (x east, y north, metres); the simulator puts the geodetic origin of the logs at its
origin.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt
from scipy import ndimage

from sonarslam.features.geometry import FloatArray

__all__ = [
    "World",
    "pool_world",
    "harbour_world",
    "drift_world",
    "random_harbour_world",
    "loop_segments",
    "rotate_points",
    "inside",
    "clearance_m",
]


@dataclass(frozen=True, eq=False)
class World:
    """Walls of a simulated place.

    Attributes
    ----------
    name : str
        Short name (``"pool"``, ``"harbour"``, ``"random"``).
    walls_m : ndarray, shape (N, 2, 2)
        Wall segments ``[[x0, y0], [x1, y1]]`` in the world frame (local East-North, m). They form
        closed loops.
    route_m : ndarray, shape (K, 2) or None
        A closed survey route (waypoints, m) that a vehicle with turn radius up to
        ``route_turn_radius_m`` can follow at least 3 m from every wall; None if the world has none.
    route_turn_radius_m : float
        Largest turn radius (m) for which ``route_m`` keeps its clearance.
    wall_gain : ndarray, shape (N,) or None
        Echo strength of each wall, a factor on the echo model's gain; None: 1 for every wall.
    wall_band_m : ndarray, shape (N,) or None
        Band thickness of each wall: the length of its echo's tail behind the face (m); None:
        the echo model's ``tail_m`` for every wall.
    wall_curve : ndarray of int, shape (N,) or None
        Index of the curved stretch a wall is a facet of (-1: a straight wall); None: all
        straight.
    wall_material : tuple of str or None
        Material of each wall (``quay``, ``breakwater``, ``hull``, ``pontoon``, ``pier``).
    layout : dict or None
        A summary of a drawn world (:func:`sonarslam.datasets.simulator.layout.drawn_world`): basins,
        channels, features, lap; None for the fixed worlds.
    """

    name: str
    walls_m: FloatArray = field(repr=False)
    route_m: FloatArray | None = field(default=None, repr=False)
    route_turn_radius_m: float = 0.0
    wall_gain: FloatArray | None = field(default=None, repr=False)
    wall_band_m: FloatArray | None = field(default=None, repr=False)
    wall_curve: npt.NDArray[np.int64] | None = field(default=None, repr=False)
    wall_material: tuple[str, ...] | None = field(default=None, repr=False)
    layout: dict[str, Any] | None = field(default=None, repr=False)

    def __post_init__(self) -> None:
        w = np.asarray(self.walls_m, dtype=np.float64)
        if w.ndim != 3 or w.shape[1:] != (2, 2) or w.shape[0] == 0:
            raise ValueError(f"World.walls_m must have shape (N, 2, 2), got {w.shape}")
        object.__setattr__(self, "walls_m", w)
        for name in ("wall_gain", "wall_band_m", "wall_curve", "wall_material"):
            v = getattr(self, name)
            if v is not None and len(v) != w.shape[0]:
                raise ValueError(f"World.{name} must have one value per wall ({w.shape[0]})")

    @property
    def bounds_m(self) -> FloatArray:
        """``(x_min, y_min, x_max, y_max)`` of the walls (m)."""
        pts = self.walls_m.reshape(-1, 2)
        return np.concatenate([pts.min(axis=0), pts.max(axis=0)])


def loop_segments(vertices_m: npt.ArrayLike) -> FloatArray:
    """Segments of the closed polygon through ``vertices_m``.

    Parameters
    ----------
    vertices_m : array_like, shape (K, 2)
        Polygon vertices (m), not repeated at the end.

    Returns
    -------
    ndarray, shape (K, 2, 2)
    """
    v = np.asarray(vertices_m, dtype=np.float64)
    return np.stack([v, np.roll(v, -1, axis=0)], axis=1)


def rotate_points(points_m: npt.ArrayLike, angle_rad: float) -> FloatArray:
    """Rotate points counter-clockwise about the origin; any shape ``(..., 2)``."""
    p = np.asarray(points_m, dtype=np.float64)
    c, s = np.cos(angle_rad), np.sin(angle_rad)
    return np.stack([c * p[..., 0] - s * p[..., 1], s * p[..., 0] + c * p[..., 1]], axis=-1)


def inside(world: World, points_m: npt.ArrayLike) -> npt.NDArray[np.bool_]:
    """Whether points are in the water (inside an odd number of wall loops).

    Parameters
    ----------
    world : World
    points_m : array_like, shape (P, 2)
        World points (m).

    Returns
    -------
    ndarray of bool, shape (P,)
    """
    p = np.atleast_2d(np.asarray(points_m, dtype=np.float64))
    a = world.walls_m[:, 0]
    b = world.walls_m[:, 1]
    px, py = p[:, 0:1], p[:, 1:2]
    straddle = (a[:, 1] > py) != (b[:, 1] > py)  # (P, S)
    dy = np.where(b[:, 1] == a[:, 1], 1.0, b[:, 1] - a[:, 1])
    x_cross = a[:, 0] + (py - a[:, 1]) * (b[:, 0] - a[:, 0]) / dy
    crossings = np.count_nonzero(straddle & (px < x_cross), axis=1)
    return np.asarray(crossings % 2 == 1)


def clearance_m(world: World, points_m: npt.ArrayLike) -> FloatArray:
    """Distance from each point to the nearest wall (m).

    Parameters
    ----------
    world : World
    points_m : array_like, shape (P, 2)

    Returns
    -------
    ndarray, shape (P,)
    """
    p = np.atleast_2d(np.asarray(points_m, dtype=np.float64))[:, None, :]
    a = world.walls_m[None, :, 0]
    ab = world.walls_m[None, :, 1] - a
    ab2 = np.maximum(np.sum(ab * ab, axis=-1), 1e-12)
    u = np.clip(np.sum((p - a) * ab, axis=-1) / ab2, 0.0, 1.0)
    d = p - (a + u[..., None] * ab)
    return np.asarray(np.sqrt(np.min(np.sum(d * d, axis=-1), axis=1)))


def _rectangle(x0: float, y0: float, x1: float, y1: float) -> FloatArray:
    return loop_segments([[x0, y0], [x1, y0], [x1, y1], [x0, y1]])


def pool_world(rotation_rad: float = math.radians(25.0)) -> World:
    """The seed paper's 2 m x 4 m test pool, with the sonar at the world origin.

    In the pool's own frame the pool spans ``[0, 2] x [0, 4]`` m and the sonar sits at
    ``(0.8, 1.5)`` m: 0.2 m and 0.5 m off the centre, 0.8 m from the nearest wall. The pool is then
    rotated by ``rotation_rad`` (counter-clockwise) about the sonar, so that no wall is square to
    the world axes.

    Parameters
    ----------
    rotation_rad : float
        Rotation of the pool in the world (rad).

    Returns
    -------
    World
        Four walls; no survey route (the sonar is stationary).
    """
    walls = _rectangle(0.0, 0.0, 2.0, 4.0) - np.array([0.8, 1.5])
    return World(name="pool", walls_m=rotate_points(walls, rotation_rad))


#: Rotation of the harbour's channel axis from East (rad).
HARBOUR_ROTATION_RAD = math.radians(20.0)


def harbour_world(rotation_rad: float = HARBOUR_ROTATION_RAD) -> World:
    """A marina-like harbour of about 310 m x 100 m.

    In the harbour's own frame (then rotated by ``rotation_rad`` about the origin): a west basin
    ``[-80, 0] x [-50, 50]`` m with a 3 m wide pier from its north wall and a moored 5 m x 20 m
    hull along its west wall, a 20 m wide, 170 m long channel ``[0, 170] x [-10, 10]`` m, and an
    east basin ``[170, 230] x [-40, 45]`` m with a pier from its south wall. The route is a
    lawnmower over the west basin, then through the channel, a loop of the east basin and back.

    Parameters
    ----------
    rotation_rad : float
        Counter-clockwise rotation of the whole harbour (rad).

    Returns
    -------
    World
    """
    outline = [
        [-80.0, -50.0], [0.0, -50.0], [0.0, -10.0], [170.0, -10.0], [170.0, -40.0],
        [198.5, -40.0], [198.5, -15.0], [201.5, -15.0], [201.5, -40.0],  # east pier
        [230.0, -40.0], [230.0, 45.0], [170.0, 45.0], [170.0, 10.0], [0.0, 10.0], [0.0, 50.0],
        [-38.5, 50.0], [-38.5, 25.0], [-41.5, 25.0], [-41.5, 50.0],  # west pier
        [-80.0, 50.0],
    ]  # fmt: skip
    hull = _rectangle(-75.0, -20.0, -70.0, 0.0)
    walls = np.concatenate([loop_segments(outline), hull])
    route = [
        [-62.0, -40.0], [-8.0, -40.0], [-8.0, -25.0], [-62.0, -25.0], [-62.0, 5.0],
        [215.0, 5.0], [215.0, 33.0], [182.0, 33.0], [182.0, -5.0], [-10.0, -5.0],
    ]  # fmt: skip
    return World(
        name="harbour",
        walls_m=rotate_points(walls, rotation_rad),
        route_m=rotate_points(np.array(route), rotation_rad),
        route_turn_radius_m=4.0,
    )


#: Rotation of the drift world from its own frame (rad).
DRIFT_ROTATION_RAD = math.radians(-30.0)


def drift_world(rotation_rad: float = DRIFT_ROTATION_RAD) -> World:
    """A harbour of another layout than :func:`harbour_world`, for long surveys that drift.

    In its own frame (then rotated by ``rotation_rad`` about the origin, its south-west corner),
    one basin ``[0, 130] x [0, 85]`` m with:

    * a **breakwater** 5 m thick from the east quay, ``[70, 130] x [32, 37]`` m: two parallel
      60 m faces 5 m apart, each seen from its own side of the basin, and a 5 m tip;
    * a north quay of three **collinear pieces** (``x`` in 0-30, 40-75, 85-130 m) between two
      10 m x 12 m docks (the gaps);
    * three **short finger piers** 2 m x 6 m off the west quay (at ``y`` = 15, 30, 45 m), which
      split it in four collinear pieces, and a 4 m x 8 m pier off the south quay (``x`` = 95 m);
    * a **moored hull** 20 m x 5 m, ``[25, 45] x [3, 8]`` m, 3 m off the south quay.

    The route (422 m: 15.6 min a lap at 0.45 m/s) runs east past the hull and the south quay,
    west along the breakwater's south face, round its tip, east along its north face, west along
    the north quay and south past the finger piers, at least 7 m from every wall: in a 1,800 s
    survey every wall is seen again about a quarter of an hour after it was first seen.

    Parameters
    ----------
    rotation_rad : float
        Counter-clockwise rotation of the whole world (rad).

    Returns
    -------
    World
    """
    outline = [
        [0.0, 0.0], [95.0, 0.0], [95.0, 8.0], [99.0, 8.0], [99.0, 0.0],  # south pier
        [130.0, 0.0], [130.0, 32.0], [70.0, 32.0], [70.0, 37.0], [130.0, 37.0],  # breakwater
        [130.0, 85.0], [85.0, 85.0], [85.0, 97.0], [75.0, 97.0], [75.0, 85.0],  # dock
        [40.0, 85.0], [40.0, 97.0], [30.0, 97.0], [30.0, 85.0],  # dock
        [0.0, 85.0], [0.0, 47.0], [6.0, 47.0], [6.0, 45.0], [0.0, 45.0],  # finger piers
        [0.0, 32.0], [6.0, 32.0], [6.0, 30.0], [0.0, 30.0],
        [0.0, 17.0], [6.0, 17.0], [6.0, 15.0], [0.0, 15.0],
    ]  # fmt: skip
    hull = _rectangle(25.0, 3.0, 45.0, 8.0)
    walls = np.concatenate([loop_segments(outline), hull])
    route = [
        [13.0, 15.0], [118.0, 15.0], [118.0, 24.0], [60.0, 24.0], [60.0, 48.0],
        [118.0, 48.0], [118.0, 70.0], [13.0, 70.0],
    ]  # fmt: skip
    return World(
        name="drift",
        walls_m=rotate_points(walls, rotation_rad),
        route_m=rotate_points(np.array(route), rotation_rad),
        route_turn_radius_m=4.0,
    )


def _grid_boundary(occupied: npt.NDArray[np.bool_]) -> FloatArray:
    """Boundary of a cell set as merged axis-aligned segments, in cell units (x = column)."""
    occ = np.pad(occupied, 1)  # cell (r, c) of occ spans x in [c-1, c], y in [r-1, r]
    segments: list[list[list[float]]] = []
    for horizontal in (True, False):
        grid = occ if horizontal else occ.T
        change = grid[1:] != grid[:-1]  # edge between line k and k+1 of the grid
        side = grid[1:] & change  # water on the upper side
        for k in range(change.shape[0]):
            j = 0
            n = change.shape[1]
            while j < n:
                if not change[k, j]:
                    j += 1
                    continue
                start = j
                while j < n and change[k, j] and side[k, j] == side[k, start]:
                    j += 1
                a, b, level = start - 1.0, j - 1.0, float(k)
                if horizontal:
                    segments.append([[a, level], [b, level]])
                else:
                    segments.append([[level, a], [level, b]])
    return np.asarray(segments, dtype=np.float64)


def random_harbour_world(rng: np.random.Generator, cell_m: float = 10.0) -> World:
    """A random rectilinear harbour, closed, tens to a few hundred metres across.

    A main basin of 8-22 x 5-10 cells, one to three side basins attached to it, and two to six
    notches (docks) cut into its edge, on a grid of ``cell_m``; the connected water containing the
    main basin's centre is kept, holes are filled, its outline is merged into straight walls,
    rotated by a random angle and centred on the origin. No survey route; use
    :func:`sonarslam.datasets.simulator.path.free_path`.

    Parameters
    ----------
    rng : numpy.random.Generator
        The only source of randomness.
    cell_m : float
        Grid cell size (m).

    Returns
    -------
    World
    """
    nx, ny = int(rng.integers(8, 23)), int(rng.integers(5, 11))
    pad = 7
    occ = np.zeros((ny + 2 * pad, nx + 2 * pad), dtype=bool)
    occ[pad : pad + ny, pad : pad + nx] = True
    for _ in range(int(rng.integers(1, 4))):
        w, h = int(rng.integers(3, 9)), int(rng.integers(3, 7))
        side = int(rng.integers(4))
        if side in (0, 1):  # south or north
            c0 = int(rng.integers(pad - w // 2, pad + nx - w // 2))
            r0 = pad - h + 1 if side == 0 else pad + ny - 1
            occ[r0 : r0 + h, max(c0, 0) : c0 + w] = True
        else:  # west or east
            r0 = int(rng.integers(pad - h // 2, pad + ny - h // 2))
            c0 = pad - w + 1 if side == 2 else pad + nx - 1
            occ[max(r0, 0) : r0 + h, c0 : c0 + w] = True
    for _ in range(int(rng.integers(2, 7))):
        w, d = int(rng.integers(1, 4)), int(rng.integers(1, 3))
        side = int(rng.integers(4))
        if side in (0, 1):
            c0 = int(rng.integers(pad + 1, pad + nx - w))
            r0 = pad if side == 0 else pad + ny - d
            occ[r0 : r0 + d, c0 : c0 + w] = False
        else:
            r0 = int(rng.integers(pad + 1, pad + ny - w))
            c0 = pad if side == 2 else pad + nx - d
            occ[r0 : r0 + w, c0 : c0 + d] = False
    labels, _ = ndimage.label(occ)
    centre = labels[pad + ny // 2, pad + nx // 2]
    occ = ndimage.binary_fill_holes(labels == centre)
    walls = _grid_boundary(occ) * cell_m
    rows, cols = np.nonzero(occ)
    centroid = (np.array([cols.mean(), rows.mean()]) + 0.5) * cell_m
    rotation = float(rng.uniform(-np.pi, np.pi))
    return World(name="random", walls_m=rotate_points(walls - centroid, rotation))
