"""Sensor faults that pass the readers: implausible samples, repeated stamps and gaps.

The readers (:mod:`sonarslam.datasets.marina`) refuse what is not a log of the kind; what remains can
still be a fault of the sensor: a spike, a stamp logged twice, a silence. Spikes and gaps are
normal at sea, so a run survives them and says so: every sample dropped or flagged here is
counted in :class:`SensorReport` (``metrics.json``: ``fault_*``, ``gap_*``) with one
:class:`sonarslam.datasets.errors.DataWarning` per kind naming the file. The limits are ``[gates]`` of
``sonarslam.toml`` (:class:`sonarslam.datasets.config.GateConfig`).

=====================================  =======================================================
fault                                  what happens
=====================================  =======================================================
repeated stamp (DVL, AHRS, GPS)        the later rows of a stamp are dropped
DVL velocity exactly (0, 0) while      the row is flagged as without bottom lock (a moving
the rows about it move                 vehicle's DVL reads its motion and noise: exact zeros
                                       are a dropout's fill)
DVL speed > ``dvl_max_speed_mps``      the row is flagged as without bottom lock
DVL velocity ``dvl_spike_sigmas``      the row is flagged as without bottom lock
scatters off both neighbours
DVL slower than ``DVL_MIN_SPEED_MPS``  a warning naming the likely unit slip (the rows are
in 90 % of its locked rows             kept: a vehicle may hold station)
AHRS rate > ``ahrs_max_rate_deg_per_s``      the sample is dropped
AHRS heading jump the gyro does        the sample is dropped (judged against the last good
not explain                            sample turned by the gyro's integral since)
GPS row without a fix, or at 0/0       dropped from the evaluation (the reader flags it)
GPS fix far from its neighbours        dropped from the evaluation
no sample for a while (any sensor)     a gap: reported; the motion model takes the DVL or
                                       AHRS sample as stale (:mod:`sonarslam.slam.model.motion`)
=====================================  =======================================================
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from sonarslam.datasets.config import GateConfig
from sonarslam.datasets.errors import DataError, DataWarning
from sonarslam.datasets.geodesy import local_en_to_geodetic
from sonarslam.datasets.qgccsv import is_qgc_csv  # the reader's own test of the header
from sonarslam.datasets.records import AttitudeSeries, DvlSeries, GpsSeries
from sonarslam.features.geometry import FloatArray

__all__ = [
    "Gaps",
    "SensorReport",
    "find_gaps",
    "gate_dvl",
    "gate_attitude",
    "gate_gps",
    "gate_beams",
    "navigation_span_s",
    "MAX_BEAMS_OUTSIDE_NAV",
    "dvl_spikes",
    "dvl_speed_quantiles",
    "DVL_MIN_SPEED_MPS",
    "check_heading_sense",
]

#: Neighbours of a GPS fix: those within this time (s).
GPS_NEIGHBOUR_WINDOW_S = 10.0
#: At most this many gap spans are listed per sensor in ``metrics.json`` (all are counted).
LISTED_GAPS = 20


@dataclass(frozen=True)
class Gaps:
    """Times without a sample of one sensor.

    Attributes
    ----------
    threshold_s : float
        A gap is longer than this (s): ``gap_periods`` median periods, at least ``min_gap_s``.
    spans_s : ndarray, shape (K, 2)
        Start (the last sample before) and end (the first after) of each gap (Unix s).
    """

    threshold_s: float
    spans_s: FloatArray

    @property
    def count(self) -> int:
        return int(self.spans_s.shape[0])

    @property
    def total_s(self) -> float:
        return float(np.sum(self.spans_s[:, 1] - self.spans_s[:, 0]))

    @property
    def longest_s(self) -> float:
        return float(np.max(self.spans_s[:, 1] - self.spans_s[:, 0], initial=0.0))


#: Samples a pass of the gates holds as temporaries at a time: the gates work through a
#: series in blocks, so that their memory beside the series' own arrays does not grow with
#: its length (at most a bool a sample for the masks of what is dropped).
BLOCK = 1 << 13


def _positive_steps(t: FloatArray, mask: np.ndarray | None) -> Iterator[FloatArray]:
    """The positive steps between consecutive samples of ``t`` (of ``t[mask]``), a block at
    a time: the values of ``np.diff(t)[np.diff(t) > 0]``, in order."""
    last: float | None = None
    for a in range(0, t.size, BLOCK):
        block = t[a : a + BLOCK] if mask is None else t[a : a + BLOCK][mask[a : a + BLOCK]]
        if not block.size:
            continue
        steps = np.diff(block) if last is None else np.diff(block, prepend=last)
        last = float(block[-1])
        yield steps[steps > 0.0]


def _kth_positive(blocks: Callable[[], Iterator[FloatArray]], k: int) -> float:
    """The ``k``-th smallest (from 0) of positive finite floats given in blocks (re-read on
    each pass): a radix selection over their bits (an order-preserving uint64 for positive
    floats), 8 bits a pass, exact, in memory of a block and 256 counts."""
    prefix = 0
    for shift in range(56, -8, -8):
        counts = np.zeros(256, dtype=np.int64)
        high = np.uint64(shift + 8)
        for block in blocks():
            u = block.view(np.uint64)
            if shift < 56:
                u = u[(u >> high) == np.uint64(prefix >> (shift + 8))]
            counts += np.bincount(
                ((u >> np.uint64(shift)) & np.uint64(0xFF)).astype(np.intp), minlength=256
            )
        cum = np.cumsum(counts)
        digit = int(np.searchsorted(cum, k, side="right"))
        k -= int(cum[digit - 1]) if digit else 0
        prefix |= digit << shift
    return float(np.array([prefix], dtype=np.uint64).view(np.float64)[0])


def _median_step(t: FloatArray, mask: np.ndarray | None) -> float:
    """``np.median`` of the positive steps of ``t`` (of ``t[mask]``), 0 without any: the same
    float, in memory of a block (:func:`_kth_positive`) rather than of three copies of ``t``."""

    def blocks() -> Iterator[FloatArray]:
        return _positive_steps(t, mask)

    n = sum(b.size for b in blocks())
    if not n:
        return 0.0
    upper = _kth_positive(blocks, n // 2)
    if n % 2:
        return upper
    return float((np.float64(_kth_positive(blocks, n // 2 - 1)) + np.float64(upper)) / 2.0)


def gap_threshold_s(t_s: FloatArray, gates: GateConfig, mask: np.ndarray | None = None) -> float:
    """The longest step (s) between two samples that is not a gap: ``gap_periods`` median
    periods of ``t_s`` (of ``t_s[mask]``), at least ``min_gap_s``."""
    return max(gates.gap_periods * _median_step(t_s, mask), gates.min_gap_s)


def find_gaps(t_s: FloatArray, gates: GateConfig, mask: np.ndarray | None = None) -> Gaps:
    """The gaps of a sensor's sample times (s, non-decreasing; only those of ``mask`` when
    given; longer than :func:`gap_threshold_s`), worked through in blocks (:data:`BLOCK`)."""
    t = np.asarray(t_s, dtype=np.float64)
    threshold = gap_threshold_s(t, gates, mask)
    spans: list[FloatArray] = []
    last: float | None = None
    for a in range(0, t.size, BLOCK):
        block = t[a : a + BLOCK] if mask is None else t[a : a + BLOCK][mask[a : a + BLOCK]]
        if not block.size:
            continue
        seq = block if last is None else np.concatenate([[last], block])
        i = np.flatnonzero(np.diff(seq) > threshold)
        if i.size:
            spans.append(np.column_stack([seq[i], seq[i + 1]]))
        last = float(block[-1])
    return Gaps(threshold, np.concatenate(spans) if spans else np.zeros((0, 2)))


@dataclass
class SensorReport:
    """What the gates found in a dataset: counts of faulty samples and gaps per sensor."""

    counts: dict[str, int] = field(default_factory=dict)
    gaps: dict[str, Gaps] = field(default_factory=dict)
    beams_outside_nav: int = 0

    def metrics(self, span_s: tuple[float, float] | None = None) -> dict[str, Any]:
        """Flat entries for ``metrics.json``: ``fault_<kind>`` counts, and per sensor
        ``gap_<sensor>_count``, ``_total_s``, ``_longest_s`` with ``gap_spans_s`` (the first
        :data:`LISTED_GAPS` spans per sensor, Unix s); only the gaps overlapping ``span_s``;
        ``beams_outside_nav``, the sonar beams outside the navigation span (:func:`gate_beams`)."""
        out: dict[str, Any] = {f"fault_{k}": v for k, v in self.counts.items()}
        out["beams_outside_nav"] = self.beams_outside_nav
        spans: dict[str, list[list[float]]] = {}
        for sensor, gaps in self.gaps.items():
            g = gaps
            if span_s is not None:
                inside = (g.spans_s[:, 1] > span_s[0]) & (g.spans_s[:, 0] < span_s[1])
                g = Gaps(g.threshold_s, g.spans_s[inside])
            out[f"gap_{sensor}_count"] = g.count
            out[f"gap_{sensor}_total_s"] = g.total_s
            out[f"gap_{sensor}_longest_s"] = g.longest_s
            if g.count:
                spans[sensor] = g.spans_s[:LISTED_GAPS].tolist()
        out["gap_spans_s"] = spans
        return out


def _warn(path: Path | None, sensor: str, message: str) -> None:
    warnings.warn(f"{path or sensor}: {message}", DataWarning, stacklevel=3)


def _warn_gaps(path: Path | None, sensor: str, gaps: Gaps, what: str) -> Gaps:
    """One warning naming the sensor's gaps (count, total, the longest and where)."""
    if gaps.count:
        longest = int(np.argmax(gaps.spans_s[:, 1] - gaps.spans_s[:, 0]))
        a, b = gaps.spans_s[longest]
        _warn(
            path,
            sensor,
            f"{gaps.count} gap(s) of the {sensor} longer than {gaps.threshold_s:.3g} s"
            f" ({gaps.total_s:.1f} s in all; the longest {b - a:.1f} s from t={a:.3f} s):"
            f" {what}",
        )
    return gaps


def _later_repeats(t_s: FloatArray) -> np.ndarray:
    """(N,) bool: rows whose stamp equals the previous row's (time never decreases)."""
    out = np.zeros(t_s.size, dtype=bool)
    np.equal(t_s[1:], t_s[:-1], out=out[1:])
    return out


def _compact(keep: np.ndarray, *arrays: np.ndarray) -> tuple[np.ndarray, ...]:
    """The rows of ``arrays`` where ``keep``, moved to the front of each in place (a block at
    a time) and returned as views of that front."""
    w = 0
    for a in range(0, keep.size, BLOCK):
        kb = keep[a : a + BLOCK]
        m = int(kb.sum())
        for x in arrays:
            x[w : w + m] = x[a : a + BLOCK][kb]
        w += m
    return tuple(x[:w] for x in arrays)


#: The DVL's scatter at a row is the one of this many successive differences about it.
DVL_SCATTER_WINDOW = 61
#: The median norm of the difference of two samples of 2-D white noise of 1-sigma ``s`` per
#: axis is ``2 sqrt(ln 2) s`` (a Rayleigh of scale ``sqrt(2) s``).
RAYLEIGH_MEDIAN_PER_SIGMA = 2.0 * math.sqrt(math.log(2.0))


def dvl_spikes(
    t_s: FloatArray, v_mps: FloatArray, valid: np.ndarray, gates: GateConfig, floor_mps: float
) -> tuple[np.ndarray, FloatArray, FloatArray]:
    """Isolated velocity spikes among the valid DVL rows: ``(spike (N,) bool, sigma (N,) m/s,
    off (N,) m/s)``.

    ``sigma`` is the DVL's scatter per axis at each valid row, the run's own and local: the
    median norm of the :data:`DVL_SCATTER_WINDOW` successive differences of the valid
    velocities about it over :data:`RAYLEIGH_MEDIAN_PER_SIGMA` (robust to the spike itself; a
    DVL that degrades raises it where it does), at least ``floor_mps`` (``[noise]
    dvl_sigma_mps``). A valid row whose velocity is farther than ``dvl_spike_sigmas * sigma``
    (horizontal norm) from both its valid neighbours', each within a gap's time
    (:func:`gap_threshold_s` of the valid rows), is a spike; ``off`` is the
    smaller of the two distances (0 where not judged). A step of the velocity (a real
    acceleration) leaves one neighbour near: not a spike. White noise of ``sigma`` per axis is
    that far from one neighbour with chance ``exp(-k^2 / 4)`` (``k`` the sigmas). Two spikes in
    a row are found as a pair (:func:`_spike_pairs`).
    """
    n = t_s.size
    spike = np.zeros(n, dtype=bool)
    off = np.zeros(n)
    sigma = np.full(n, np.nan)
    idx = np.flatnonzero(valid)
    if idx.size < 3 or gates.dvl_spike_sigmas <= 0.0:
        return spike, sigma, off
    d = np.diff(v_mps[idx], axis=0)  # (M - 1, 2)
    jump = np.hypot(d[:, 0], d[:, 1])
    del d
    half = DVL_SCATTER_WINDOW // 2
    padded = np.pad(jump, half, mode="edge")
    windows = np.lib.stride_tricks.sliding_window_view(padded, 2 * half + 1)
    local = np.empty(jump.size)
    for a in range(0, jump.size, BLOCK):
        local[a : a + BLOCK] = np.median(windows[a : a + BLOCK], axis=1)
    del padded, windows
    # row idx[j] (1 <= j <= M - 2) lies between differences j - 1 and j
    row_sigma = np.maximum(np.maximum(local[:-1], local[1:]) / RAYLEIGH_MEDIAN_PER_SIGMA, floor_mps)
    near = np.diff(t_s[idx]) <= gap_threshold_s(t_s, gates, valid)
    judged = near[:-1] & near[1:]
    least = np.where(judged, np.minimum(jump[:-1], jump[1:]), 0.0)
    off[idx[1:-1]] = least
    sigma[idx[1:-1]] = row_sigma
    spike[idx[1:-1]] = least > gates.dvl_spike_sigmas * row_sigma
    pair, pair_off = _spike_pairs(v_mps[idx], near, row_sigma, gates.dvl_spike_sigmas)
    off[idx[1:-1]] = np.where(pair, pair_off, off[idx[1:-1]])
    spike[idx[1:-1]] |= pair
    return spike, sigma, off


def _spike_pairs(
    v_mps: FloatArray, near: np.ndarray, row_sigma: FloatArray, k: float
) -> tuple[np.ndarray, FloatArray]:
    """Two spikes in a row among ``M`` valid rows (each has the other as a close neighbour, so
    the isolated test misses both): ``(pair (M - 2,) bool, off (M - 2,) m/s)`` for the inner rows
    ``1 .. M - 2``.

    Rows ``j, j + 1`` are a pair when both are more than ``k`` times the scatter (the larger of
    the two rows' ``row_sigma``) off the rows either side of them (``j - 1`` and ``j + 2``),
    which agree with each other within ``k`` times it, all four within a gap's time (``near``,
    (M - 1,)). A step of the velocity leaves the rows either side apart: not a pair. ``off`` is
    the least of the four distances (0 where not a pair)."""
    m = v_mps.shape[0]
    pair = np.zeros(m - 2, dtype=bool)
    off = np.zeros(m - 2)
    if m < 4:
        return pair, off
    before, a, b, after = v_mps[:-3], v_mps[1:-2], v_mps[2:-1], v_mps[3:]  # (M - 3, 2) each

    def dist(p: FloatArray, q: FloatArray) -> FloatArray:
        return np.hypot(p[:, 0] - q[:, 0], p[:, 1] - q[:, 1])

    least = np.minimum.reduce([dist(a, before), dist(a, after), dist(b, before), dist(b, after)])
    limit = k * np.maximum(row_sigma[:-1], row_sigma[1:])
    hit = near[:-2] & near[1:-1] & near[2:] & (least > limit) & (dist(before, after) <= limit)
    # pair j (rows j + 1, j + 2 of the M) marks inner rows j and j + 1
    pair[:-1] |= hit
    pair[1:] |= hit
    off[:-1] = np.where(hit, least, off[:-1])
    off[1:] = np.where(hit, np.maximum(off[1:], least), off[1:])
    return pair, off


#: The DVL's horizontal speed in 90 % of its locked rows under this (m/s) is implausible for an
#: AUV or ASC survey: ten times below ~0.2 m/s, the slow end of such surveys (72 m an hour), is a
#: unit slip rather than a vehicle (a log in m/s read as the marina layout's cm/s is 100 times
#: slow). At rest a DVL reads its own noise (a 1-sigma ``s`` per axis gives a p90 speed of
#: ``2.15 s``), above it for most DVLs, while a unit slip shrinks the noise with the motion; a
#: quiet DVL on a vehicle that hovers the whole run can be under it, which the warning allows.
#: docs/bad-input.md gives the marina's and the simulator's speeds against it.
DVL_MIN_SPEED_MPS = 0.02


def dvl_speed_quantiles(dvl: DvlSeries, quantiles: tuple[int, ...] = (50, 90)) -> dict[int, float]:
    """Percentiles (``quantiles``, 0-100) of the DVL's horizontal speed over its locked rows
    (m/s); NaN without a locked row."""
    v = dvl.v_mps[dvl.valid]
    if v.shape[0] == 0:
        return {q: math.nan for q in quantiles}
    speed = np.hypot(v[:, 0], v[:, 1])
    return {q: float(np.percentile(speed, q)) for q in quantiles}


def _is_qgc_export(path: Path | None) -> bool:
    if path is None or path.suffix.lower() != ".csv":
        return False
    return is_qgc_csv(path)


def _dvl_unit(path: Path | None, slow: bool = False) -> str:
    """Where the DVL's velocities come from and the unit the reader takes them in, in words;
    ``slow``: for velocities far too small (a unit larger than the one read), else too large."""
    if _is_qgc_export(path):
        return (
            "QGroundControl's CSV export rounds the autopilot's velocity to 0.1 m/s, in the speed"
            " unit its settings display (m/s by default): a vehicle slower than 0.05 m/s reads"
            " exactly 0"
        )
    if path is not None and path.name.endswith("_DVL.log"):
        return (
            "the marina layout's bottomVelX/Y columns are read as cm/s, divided by 100, and no"
            " setting takes another unit: a log written in m/s reads 100 times slow, one in mm/s"
            " 10 times fast"
        )
    if path is None:
        return "the DVL's velocities are taken as m/s (DvlSeries.v_mps)"
    if path.suffix.lower() == ".csv":
        return "the navigation CSV's dvl_vx_mps/dvl_vy_mps are read as m/s"
    if slow:
        return (
            "the DVL's velocities are read as m/s, ROS's unit: check the unit the driver"
            " publishes, and that the topic is the DVL's bottom velocity"
        )
    return (
        "the DVL's velocities are read as m/s, ROS's unit: a driver publishing cm/s reads 100"
        " times fast"
    )


def _check_dvl_speed(dvl: DvlSeries) -> None:
    """Warn when the vehicle is implausibly slow for its whole run (:data:`DVL_MIN_SPEED_MPS`),
    naming the likely cause: the velocities' unit."""
    q = dvl_speed_quantiles(dvl, (50, 90))
    if not q[90] < DVL_MIN_SPEED_MPS:
        return
    _warn(
        dvl.path,
        "DVL",
        f"the vehicle is implausibly slow: the DVL's speed over its locked rows has median"
        f" {q[50]:.4f} m/s and 90th percentile {q[90]:.4f} m/s, under the"
        f" {DVL_MIN_SPEED_MPS:g} m/s that any AUV or ASC survey exceeds (ten times below the"
        f" slowest, ~0.2 m/s): unless the vehicle hovered the whole run, the velocities' unit is"
        f" likely wrong ({_dvl_unit(dvl.path, slow=True)}) and every estimate moves that much"
        " too little",
    )


def _dvl_lock_flag(path: Path | None) -> str:
    """Where the DVL's bottom lock comes from, in words (to mark a dropout there)."""
    if path is None:
        return "give dvl_valid (False where the DVL had no bottom lock)"
    if _is_qgc_export(path):
        return (
            "QGroundControl's CSV export has no lock flag (its velocity is the autopilot's"
            " estimate): give the DVL's own velocities (a .tlog's VISION_POSITION_DELTA or the"
            " A50's JSON) for its bottom lock"
        )
    if path.suffix.lower() == ".csv":
        return (
            "give the CSV a dvl_valid column (0 without bottom lock; without the column every"
            " row counts as locked)"
        )
    if path.name.endswith("_DVL.log"):
        return "the log's bottom-lock status marks a dropout"
    return "the DVL message's lock flag (or a covariance) marks a dropout"


#: A locked row of exactly (0, 0) is a dropout's fill when the locked rows about it move faster
#: than this (m/s): a moving vehicle's DVL reads its motion and noise; a hovering one's, at a
#: DVL's resolution (a millimetre a second), can read exact zeros.
ZERO_FILL_MIN_SPEED_MPS = 0.05


def _exact_zeros(v_mps: FloatArray, valid: np.ndarray, resolution_mps: float = 0.0) -> np.ndarray:
    """(N,) bool: locked rows whose velocity is exactly (0, 0) while the vehicle moves (the
    median speed of the two locked non-zero rows either side over
    :data:`ZERO_FILL_MIN_SPEED_MPS` plus ``resolution_mps``, the quantum a log rounds the
    velocities to: there a vehicle under half of it reads 0, and one at its quantum beside;
    a rounded log's rows all zero are a vehicle that held still, a DVL's a dead stream)."""
    out = valid & (v_mps[:, 0] == 0.0) & (v_mps[:, 1] == 0.0)
    zeros = np.flatnonzero(out)
    moving = np.flatnonzero(valid & ~out)
    if zeros.size == 0:
        return out
    if moving.size == 0:  # every locked row zero: no motion to judge them by
        return out if resolution_mps <= 0.0 else np.zeros_like(out)
    speed = np.hypot(v_mps[moving, 0], v_mps[moving, 1])
    k = np.searchsorted(moving, zeros)
    around = np.stack([np.clip(k + d, 0, moving.size - 1) for d in (-2, -1, 0, 1)], axis=1)
    limit = ZERO_FILL_MIN_SPEED_MPS + resolution_mps
    out[zeros[np.median(speed[around], axis=1) <= limit]] = False
    return out


def gate_dvl(
    dvl: DvlSeries, gates: GateConfig, report: SensorReport, noise_sigma_mps: float = 0.0
) -> DvlSeries:
    """Drop repeated stamps; flag rows of exactly zero velocity, rows faster than
    ``dvl_max_speed_mps``, and isolated velocity spikes (:func:`dvl_spikes`, whose scatter is
    at least ``noise_sigma_mps``, the ``[noise] dvl_sigma_mps``), as without lock.

    A DVL with bottom lock on a moving vehicle reads its motion and noise, never exactly
    (0, 0): exact zeros there are what a logger or a driver writes for a dropout when it has
    no lock flag to give (a CSV without its ``dvl_valid`` column). Taken as locked they would
    stop the vehicle; taken as without lock they widen its uncertainty (the conservative
    side). A hovering vehicle's DVL, at its resolution, can read exact zeros: those are kept
    (:data:`ZERO_FILL_MIN_SPEED_MPS`).

    In place: the series' arrays are compacted and its ``valid`` cleared where flagged, and the
    series returned holds views of them (give it arrays it may change)."""
    repeat = _later_repeats(dvl.t)
    n_repeat = int(repeat.sum())
    t, v, valid, heading = dvl.t, dvl.v_mps, dvl.valid, dvl.heading_rad
    if n_repeat:
        t, v, valid, heading = _compact(~repeat, t, v, valid, heading)
    del repeat
    zero = _exact_zeros(v, valid, dvl.resolution_mps)
    n_zero = int(zero.sum())
    report.counts["dvl_zero_velocity"] = n_zero
    if n_zero:
        first = float(t[np.flatnonzero(zero)[0]])
        _warn(
            dvl.path,
            "DVL",
            f"{n_zero} of the {int(valid.sum())} locked row(s) read exactly (0, 0) m/s, taken"
            f" as without bottom lock (first at t={first:.3f} s): a moving vehicle's DVL reads"
            f" its motion and noise, never exact zeros, so these are a dropout's fill;"
            f" {_dvl_lock_flag(dvl.path)}",
        )
        valid &= ~zero
    del zero
    fast = np.zeros(t.size, dtype=bool)
    for a in range(0, t.size, BLOCK):
        vb = v[a : a + BLOCK]
        with np.errstate(over="ignore"):
            fast[a : a + BLOCK] = valid[a : a + BLOCK] & ~(
                np.hypot(vb[:, 0], vb[:, 1]) <= gates.dvl_max_speed_mps
            )
    n_fast = int(fast.sum())
    n_valid = int(valid.sum())
    report.counts["dvl_repeated_stamps"] = n_repeat
    report.counts["dvl_speed_spikes"] = n_fast
    if n_repeat:
        _warn(dvl.path, "DVL", f"dropped {n_repeat} row(s) repeating a stamp")
    if n_fast:
        first = float(t[np.flatnonzero(fast)[0]])
        _warn(
            dvl.path,
            "DVL",
            f"{n_fast} row(s) faster than {gates.dvl_max_speed_mps:g} m/s taken as"
            f" without bottom lock (first at t={first:.3f} s)"
            + (
                f"; that is {n_fast} of the {n_valid} locked rows: the velocities' unit is"
                f" likely wrong ({_dvl_unit(dvl.path)})"
                if 2 * n_fast > n_valid
                else ""
            ),
        )
        valid &= ~fast
    del fast
    spike, sigma, off = dvl_spikes(t, v, valid, gates, noise_sigma_mps)
    n_spike = int(spike.sum())
    report.counts["dvl_velocity_spikes"] = n_spike
    if n_spike:
        i = int(np.flatnonzero(spike)[0])
        _warn(
            dvl.path,
            "DVL",
            f"{n_spike} row(s) whose velocity is more than {gates.dvl_spike_sigmas:g} times the"
            f" DVL's scatter off both neighbours (two in a row: off the rows either side) taken"
            " as without bottom lock"
            f" (first at t={float(t[i]):.3f} s, {float(off[i]):.3g} m/s off, the scatter there"
            f" {float(sigma[i]):.3g} m/s; [gates]"
            " dvl_spike_sigmas)",
        )
        valid &= ~spike
    del spike, sigma, off
    out = DvlSeries(t, v, valid, heading, dvl.path, dvl.resolution_mps)
    _check_dvl_speed(out)
    report.gaps["dvl"] = _warn_gaps(
        dvl.path,
        "DVL",
        find_gaps(out.t, gates, out.valid),
        "its velocity is held with a growing uncertainty, then taken as unknown",
    )
    return out


#: The gyro's yaw rate and the heading's change must agree in sign: a correlation below this
#: over the run is a heading in another convention than the gyro's (NED beside ENU).
MIN_GYRO_HEADING_CORRELATION = -0.5
#: The windows (s) over which the heading's and the gyro's changes are compared.
HEADING_SENSE_WINDOW_S = 5.0
#: Turning (rad) the gyro must show before the check says anything.
MIN_TURN_FOR_SENSE_RAD = math.radians(90.0)


def check_heading_sense(
    path: Path, what: str, t_s: FloatArray, yaw_rad: FloatArray, rate_rad_per_s: FloatArray
) -> None:
    """A :class:`DataError` naming ``path`` (``what``: which heading turns against which
    gyro, in the source's words) when the AHRS heading turns against the gyro's ``z`` rate
    over the run: the correlation of their changes over :data:`HEADING_SENSE_WINDOW_S`
    windows (the heading's own noise averaged out) below :data:`MIN_GYRO_HEADING_CORRELATION`
    is a heading in NED (clockwise) beside an ENU gyro, or the other way. Silent when the
    gyro reads nothing or the run hardly turns (:data:`MIN_TURN_FOR_SENSE_RAD`). Every reader
    of a heading with its gyro checks it here (bags, navigation CSVs)."""
    if t_s.size < 3 or not t_s[-1] - t_s[0] > 2.0 * HEADING_SENSE_WINDOW_S:
        return
    gyro = np.concatenate(
        [[0.0], np.cumsum(0.5 * (rate_rad_per_s[1:] + rate_rad_per_s[:-1]) * np.diff(t_s))]
    )
    edges = np.arange(t_s[0], t_s[-1], HEADING_SENSE_WINDOW_S)
    d_heading = np.diff(np.interp(edges, t_s, np.unwrap(yaw_rad)))
    d_gyro = np.diff(np.interp(edges, t_s, gyro))
    ok = np.isfinite(d_heading) & np.isfinite(d_gyro)
    d_heading, d_gyro = d_heading[ok], d_gyro[ok]
    power = float(np.sqrt(np.sum(d_heading**2) * np.sum(d_gyro**2)))
    if not power > 0.0 or float(np.sum(np.abs(d_gyro))) < MIN_TURN_FOR_SENSE_RAD:
        return
    correlation = float(np.sum(d_heading * d_gyro)) / power
    if correlation < MIN_GYRO_HEADING_CORRELATION:
        raise DataError(
            path,
            None,
            f"{what} (correlation {correlation:+.2f} over the run): the heading is not ENU"
            " (REP-103: counter-clockwise from East; NED's heading psi turns clockwise, its"
            " ENU yaw is pi/2 - psi) or the gyro is not; convert them to one convention",
        )


#: Samples of the AHRS heading-jump pass held as Python floats at a time.
ATTITUDE_BLOCK = BLOCK


def gate_attitude(att: AttitudeSeries, gates: GateConfig, report: SensorReport) -> AttitudeSeries:
    """Drop repeated stamps, rate spikes and heading jumps the gyro does not explain.

    In place: the series' arrays are compacted, and the series returned holds views of them
    (give it arrays it may change)."""
    repeat = _later_repeats(att.t)
    limit = math.radians(gates.ahrs_max_rate_deg_per_s)
    spike = np.zeros(att.t.size, dtype=bool)
    for a in range(0, att.t.size, BLOCK):
        spike[a : a + BLOCK] = ~repeat[a : a + BLOCK] & ~(
            np.abs(att.yaw_rate_rad_per_s[a : a + BLOCK]) <= limit
        )
    n_repeat, n_spike = int(repeat.sum()), int(spike.sum())
    t, yaw, rate = att.t, att.yaw_rad, att.yaw_rate_rad_per_s
    if n_repeat or n_spike:
        t, yaw, rate = _compact(~(repeat | spike), t, yaw, rate)
    del repeat, spike
    tol0, drift = (
        math.radians(gates.ahrs_max_jump_deg),
        math.radians(gates.ahrs_jump_drift_deg_per_s),
    )
    good = np.ones(t.size, dtype=bool)
    # one pass in plain floats (10^4-10^6 samples), a block at a time: the lists of floats cost
    # 4x the arrays, so a block bounds them whatever the run's length. The gyro's trapezoidal
    # integral from the first sample (rad) is summed on, block by block, in the order
    # np.cumsum sums it whole.
    ref_t, ref_y, ref_g = (float(t[0]), float(yaw[0]), 0.0) if t.size else (0, 0, 0)
    carry = 0.0
    for a in range(1, t.size, ATTITUDE_BLOCK):
        b = min(a + ATTITUDE_BLOCK, t.size)
        steps = 0.5 * (rate[a:b] + rate[a - 1 : b - 1]) * (t[a:b] - t[a - 1 : b - 1])
        gyro = np.cumsum(np.concatenate([[carry], steps]))[1:]
        carry = float(gyro[-1])
        ts, ys, gs = t[a:b].tolist(), yaw[a:b].tolist(), gyro.tolist()
        for k in range(b - a):
            miss = (ys[k] - ref_y - (gs[k] - ref_g) + math.pi) % (2.0 * math.pi) - math.pi
            if abs(miss) <= tol0 + drift * (ts[k] - ref_t):
                ref_t, ref_y, ref_g = ts[k], ys[k], gs[k]
            else:
                good[a + k] = False
    jumps = int((~good).sum())
    report.counts["ahrs_repeated_stamps"] = n_repeat
    report.counts["ahrs_rate_spikes"] = n_spike
    report.counts["ahrs_heading_jumps"] = jumps
    for n, what in (
        (n_repeat, "repeating a stamp"),
        (n_spike, f"with a yaw rate beyond {gates.ahrs_max_rate_deg_per_s:g} deg/s"),
        (jumps, f"whose heading jumps more than {gates.ahrs_max_jump_deg:g} deg off the gyro's"),
    ):
        if n:
            _warn(att.path, "AHRS", f"dropped {n} sample(s) {what}")
    if jumps:
        t, yaw, rate = _compact(good, t, yaw, rate)
    out = AttitudeSeries(t, yaw, rate, att.path)
    report.gaps["ahrs"] = _warn_gaps(
        att.path,
        "AHRS",
        find_gaps(out.t, gates),
        "the heading is held with a growing uncertainty",
    )
    return out


def gate_gps(gps: GpsSeries, gates: GateConfig, report: SensorReport) -> GpsSeries | None:
    """Drop rows without a fix (or at 0/0), repeated stamps and fixes far from their
    neighbours' median; the origin moves to the first fix kept. None when none is left."""
    fix = np.ones(gps.t.size, dtype=bool) if gps.fix is None else gps.fix
    repeat = _later_repeats(gps.t)
    keep = fix & ~repeat
    outlier = np.zeros(gps.t.size, dtype=bool)
    outlier[keep] = _outliers(gps.t[keep], gps.en_m[keep], gates)
    keep &= ~outlier
    report.counts["gps_no_fix"] = int((~fix).sum())
    report.counts["gps_repeated_stamps"] = int((fix & repeat).sum())
    report.counts["gps_outliers"] = int(outlier.sum())
    for n, what in (
        (int((~fix).sum()), "without a fix (status or 0/0)"),
        (int((fix & repeat).sum()), "repeating a stamp"),
        (int(outlier.sum()), f"more than {gates.gps_max_jump_m:g} m off their neighbours"),
    ):
        if n:
            _warn(gps.path, "GPS", f"dropped {n} fix(es) {what} from the evaluation")
    if not keep.any():
        return None
    t, en = gps.t[keep], gps.en_m[keep]
    origin = gps.origin_lat_lon_deg
    if np.any(en[0] != 0.0):  # the reader's origin fix was dropped: move to the first kept
        lat, lon = local_en_to_geodetic(en[:1, 0], en[:1, 1], *origin)
        origin = (float(lat[0]), float(lon[0]))
        en = en - en[0]
    out = GpsSeries(t.copy(), en.copy(), origin, None, gps.path)
    report.gaps["gps"] = _warn_gaps(
        gps.path, "GPS", find_gaps(out.t, gates), "the ATE has no reference there"
    )
    return out


def _outliers(t_s: FloatArray, en_m: FloatArray, gates: GateConfig) -> np.ndarray:
    """(N,) bool: fixes farther than ``gps_max_jump_m`` + ``dvl_max_speed_mps`` x (median
    time to the neighbours) from the median of their neighbours within 10 s (at least 2)."""
    n = t_s.size
    out = np.zeros(n, dtype=bool)
    lo = np.searchsorted(t_s, t_s - GPS_NEIGHBOUR_WINDOW_S, side="left")
    hi = np.searchsorted(t_s, t_s + GPS_NEIGHBOUR_WINDOW_S, side="right")
    size = hi - lo - 1  # the neighbours of each fix: its window without itself
    # the fixes with the same count of neighbours at once (a few counts: the fixes come at a
    # steady rate); each median is the one of that fix's neighbours alone
    for m in np.unique(size[size >= 2]):
        ks = np.flatnonzero(size == m)
        j = np.arange(m)
        idx = lo[ks, None] + j + (j >= (ks - lo[ks])[:, None])  # (G, m): the window but k
        centre = np.median(en_m[idx], axis=1)  # (G, 2)
        gap_s = np.median(np.abs(t_s[idx] - t_s[ks, None]), axis=1)
        allowance = gates.gps_max_jump_m + gates.dvl_max_speed_mps * gap_s
        miss = en_m[ks] - centre
        out[ks] = np.hypot(miss[:, 0], miss[:, 1]) > allowance
    return out


def navigation_span_s(dvl: DvlSeries, attitude: AttitudeSeries) -> tuple[float, float]:
    """The time span covered by both the DVL and the AHRS (Unix s): where the vehicle can be
    navigated, and the only sonar beams a run uses."""
    return (
        max(float(dvl.t[0]), float(attitude.t[0])),
        min(float(dvl.t[-1]), float(attitude.t[-1])),
    )


#: More than this share of the sonar's beams outside the navigation span is warned of: a
#: navigation that covers part of the sonar's log (the rest is dropped). Loggers started a
#: little apart leave a few percent out: the marina's sonar starts ~183 s before its DVL, 5.4 %
#: of its beams (docs/bad-input.md).
MAX_BEAMS_OUTSIDE_NAV = 0.10


def gate_beams(
    t_s: FloatArray,
    gates: GateConfig,
    report: SensorReport,
    path: Path | None = None,
    nav_span_s: tuple[float, float] | None = None,
) -> None:
    """The sonar's gaps (its beams are not gated: a beam is evidence, not a state), and its
    beams outside the navigation span (:func:`navigation_span_s`, when given): counted in
    ``report.beams_outside_nav``, and a warning naming the counts and the spans when more than
    :data:`MAX_BEAMS_OUTSIDE_NAV` of them."""
    gaps = find_gaps(t_s, gates) if t_s.size else Gaps(0.0, np.zeros((0, 2)))
    report.gaps["sonar"] = _warn_gaps(path, "sonar", gaps, "no line can correct the navigation")
    if nav_span_s is None or not t_s.size:
        return
    t0, t1 = nav_span_s
    before = int(np.searchsorted(t_s, t0, side="left"))
    after = int(t_s.size - np.searchsorted(t_s, t1, side="right"))
    outside = before + after
    report.beams_outside_nav = outside
    if outside > MAX_BEAMS_OUTSIDE_NAV * t_s.size:
        _warn(
            path,
            "sonar",
            f"{outside} of the {t_s.size} sonar beams ({100.0 * outside / t_s.size:.1f} %) lie"
            f" outside the navigation span and are not used ({before} before it, {after} after):"
            f" the beams cover t={float(t_s[0]):.3f}-{float(t_s[-1]):.3f} s, the navigation (DVL"
            f" and AHRS both logging) t={t0:.3f}-{t1:.3f} s; is the navigation file a part of"
            " the run?",
        )
