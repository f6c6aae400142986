"""A dataset from numpy arrays: the in-memory source, checked as the file readers check theirs.

:func:`dataset_from_arrays` takes the sonar beams (times, transducer angles, intensities), the DVL
(times, velocities in the DVL frame, bottom lock), the AHRS (times, yaw, yaw rate) and an
optional GPS (latitude and longitude), with a :class:`sonarslam.datasets.config.DatasetConfig`
that the caller must give (a calibration is never another dataset's). The arrays are checked
(shape, finite values, times that never go backwards: a :class:`DataError` naming the parameter
and the first bad row), then run through the same plausibility gates as the file readers
(:mod:`sonarslam.datasets.gates`: repeated stamps, spikes, heading jumps, gaps, GPS outliers) and
the same DVL/AHRS overlap check. The ROS bag reader builds its datasets through it.

Frames and units are those of :mod:`sonarslam.datasets.records`: times in Unix s (any epoch, one
clock for all sensors), yaw counter-clockwise from East (rad) of the AHRS frame, DVL velocities in
the DVL frame (m/s), transducer angles as the head reports them (rad; ``[sonar] angle_sense`` turns
them into bearings), intensities uint8 with bin ``i`` at ``(i + 1) * bin_size_m``.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from sonarslam.datasets.config import DatasetConfig
from sonarslam.datasets.dataset import Dataset, check_overlap
from sonarslam.datasets.errors import DataError
from sonarslam.datasets.gates import (
    SensorReport,
    gate_attitude,
    gate_beams,
    gate_dvl,
    gate_gps,
    navigation_span_s,
)
from sonarslam.datasets.geodesy import geodetic_to_local_en
from sonarslam.datasets.records import AttitudeSeries, BeamSeries, DvlSeries, GpsSeries
from sonarslam.sonar.beam import intensities_problem

__all__ = ["dataset_from_arrays", "degrees_row", "gated_dataset"]


def _array(root: Path, name: str, value: npt.ArrayLike, shape: tuple[int | None, ...]) -> Any:
    """``value`` as a float64 array of ``shape`` (None: any length) with finite values: a copy
    (the gates compact the navigation's arrays in place; the caller's stay as given)."""
    try:
        a = np.array(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise DataError(root, None, f"{name} is not an array of numbers") from None
    if a.ndim != len(shape) or any(
        n is not None and n != m for n, m in zip(shape, a.shape, strict=True)
    ):
        raise DataError(root, None, f"{name} must have shape {shape}, got {a.shape}")
    bad = ~np.isfinite(a) if a.ndim == 1 else ~np.all(np.isfinite(a.reshape(a.shape[0], -1)), 1)
    if bad.any():
        raise DataError(root, None, f"{name}: row {int(np.flatnonzero(bad)[0])} is not finite")
    return a


def _times(root: Path, name: str, value: npt.ArrayLike) -> Any:
    t = _array(root, name, value, (None,))
    back = np.flatnonzero(np.diff(t) < 0.0)
    if back.size:
        i = int(back[0]) + 1
        raise DataError(
            root,
            None,
            f"{name}: row {i} ({t[i]:.6f} s) is earlier than row {i - 1} ({t[i - 1]:.6f} s)",
        )
    return t


def degrees_row(values: Any, unwrapped: bool = False) -> tuple[int, str] | None:
    """The first row of angles given in degrees for radians and why, None when none shows:
    beyond 2 pi in magnitude; for a series that may be unwrapped (``unwrapped``: any branch,
    turns counted on), its first row beyond 2 pi (``np.unwrap`` starts where its input does)
    or a step of more than 3 pi from one row to the next (no wrap of radians is that large; a
    wrap of degrees is 360). Every reader of yaw in radians checks it here."""
    a = np.asarray(values, dtype=np.float64)
    lim = 2.0 * np.pi
    if not unwrapped:
        bad = np.flatnonzero(np.abs(a) > lim)
        why = "is beyond 2 pi rad"
    elif a.size and abs(a[0]) > lim:
        bad, why = (
            np.zeros(1, dtype=np.int64),
            "is beyond 2 pi rad (an unwrapped yaw starts within it)",
        )
    else:
        bad = np.flatnonzero(np.abs(np.diff(a)) > 1.5 * lim) + 1
        why = "is more than 3 pi rad from the row before"
    return (int(bad[0]), why) if bad.size else None


def _check_radians(root: Path, name: str, values: Any, unwrapped: bool = False) -> None:
    """A :class:`DataError` naming ``name`` and the first row of :func:`degrees_row`."""
    found = degrees_row(values, unwrapped)
    if found is not None:
        i, why = found
        a = float(np.asarray(values, dtype=np.float64)[i])
        raise DataError(root, None, f"{name}: row {i} ({a:g}) {why}: degrees? (np.radians)")


def dataset_from_arrays(
    config: DatasetConfig,
    *,
    beam_t_s: npt.ArrayLike,
    beam_angle_rad: npt.ArrayLike,
    beam_intensities: npt.ArrayLike,
    dvl_t_s: npt.ArrayLike,
    dvl_v_mps: npt.ArrayLike,
    ahrs_t_s: npt.ArrayLike,
    ahrs_yaw_rad: npt.ArrayLike,
    dvl_valid: npt.ArrayLike | None = None,
    ahrs_yaw_rate_rad_per_s: npt.ArrayLike | None = None,
    gps_t_s: npt.ArrayLike | None = None,
    gps_lat_lon_deg: npt.ArrayLike | None = None,
    thresholded: bool = False,
    name: str = "arrays",
    root: str | Path | None = None,
    calibration: str = "given with the arrays (dataset_from_arrays)",
) -> Dataset:
    """A :class:`sonarslam.datasets.source.Dataset` from arrays, checked and gated.

    Parameters
    ----------
    config : DatasetConfig
        The sonar head, mountings and noise (required: ``DatasetConfig()`` is the neutral one).
    beam_t_s, beam_angle_rad : array, shape (B,)
        Beam times (s, non-decreasing) and transducer angles as the head reports them (rad,
        within 2 pi of zero).
    beam_intensities : array of uint8, shape (B, config.sonar.n_bins)
    dvl_t_s : array, shape (D,)
    dvl_v_mps : array, shape (D, 2)
        Bottom velocity in the DVL frame (m/s).
    ahrs_t_s, ahrs_yaw_rad : array, shape (A,)
        Yaw of the AHRS frame, counter-clockwise from East (rad; REP-103 ENU), wrapped in any
        branch or unwrapped (then starting within 2 pi of zero, as ``np.unwrap`` of wrapped
        angles does). A series in degrees is refused where it shows (its first row beyond 2 pi,
        or a wrap of 360); one that starts within 6.3 deg of East and never wraps cannot be
        told from radians.
    dvl_valid : array of bool, shape (D,), optional
        Bottom lock (default: every row).
    ahrs_yaw_rate_rad_per_s : array, shape (A,), optional
        The gyro's z rate (rad/s, CCW); default: the heading's own change between samples
        (then take ``[motion] yaw_rate_source = "heading"``).
    gps_t_s : array, shape (G,), optional
    gps_lat_lon_deg : array, shape (G, 2), optional
        WGS-84 fixes: a ruler for the evaluation, never an input; the local East-North frame's
        origin is the first fix.
    thresholded : bool
        The intensities are 0/255 masks.
    name, root, calibration
        The dataset's name, the path its messages name (default ``<name>``) and where its
        calibration came from (:attr:`Dataset.calibration`).

    Raises
    ------
    DataError
        A wrong shape, a value that is not finite, times going backwards, angles in degrees
        (naming the parameter and the row), intensities not of ``config.sonar.n_bins`` bins, DVL and AHRS that do not
        overlap. Faults that pass are gated with counted warnings.
    """
    where = Path(root) if root is not None else Path(f"<{name}>")
    bt = _times(where, "beam_t_s", beam_t_s)
    angle = _array(where, "beam_angle_rad", beam_angle_rad, (bt.size,))
    _check_radians(where, "beam_angle_rad", angle)
    bins = np.asarray(beam_intensities)
    n_bins = config.sonar.n_bins
    if bins.shape != (bt.size, n_bins):
        raise DataError(
            where,
            None,
            f"beam_intensities must have shape ({bt.size}, {n_bins}) ([sonar] n_bins), got"
            f" {bins.shape}",
        )
    problem = intensities_problem(bins)
    if problem is not None:
        raise DataError(where, None, f"beam_intensities {problem}")
    dt = _times(where, "dvl_t_s", dvl_t_s)
    v = _array(where, "dvl_v_mps", dvl_v_mps, (dt.size, 2))
    valid = np.ones(dt.size, dtype=bool) if dvl_valid is None else np.array(dvl_valid, bool)
    if valid.shape != (dt.size,):
        raise DataError(where, None, f"dvl_valid must have shape ({dt.size},), got {valid.shape}")
    at = _times(where, "ahrs_t_s", ahrs_t_s)
    yaw = _array(where, "ahrs_yaw_rad", ahrs_yaw_rad, (at.size,))
    _check_radians(where, "ahrs_yaw_rad", yaw, unwrapped=True)
    if ahrs_yaw_rate_rad_per_s is None:
        rate = (
            np.gradient(np.unwrap(yaw), at)
            if at.size > 1 and np.all(np.diff(at) > 0)
            else (np.zeros(at.size))
        )
    else:
        rate = _array(where, "ahrs_yaw_rate_rad_per_s", ahrs_yaw_rate_rad_per_s, (at.size,))
    gps = None
    if (gps_t_s is None) != (gps_lat_lon_deg is None):
        raise DataError(where, None, "gps_t_s and gps_lat_lon_deg go together")
    if gps_t_s is not None and gps_lat_lon_deg is not None:
        gt = _times(where, "gps_t_s", gps_t_s)
        ll = _array(where, "gps_lat_lon_deg", gps_lat_lon_deg, (gt.size, 2))
        if gt.size == 0:
            raise DataError(where, None, "gps_t_s is empty: leave the GPS out instead")
        if np.any(np.abs(ll[:, 0]) > 90.0) or np.any(np.abs(ll[:, 1]) > 180.0):
            raise DataError(where, None, "gps_lat_lon_deg: a latitude or longitude out of range")
        lat0, lon0 = float(ll[0, 0]), float(ll[0, 1])
        gps = GpsSeries(
            gt, geodetic_to_local_en(ll[:, 0], ll[:, 1], lat0, lon0), (lat0, lon0), None, None
        )
    beams = BeamSeries(bt, angle, bins, thresholded)
    if config.sonar_time_offset_s:
        beams = beams.shifted(config.sonar_time_offset_s)
    return gated_dataset(
        name,
        where,
        config,
        beams,
        DvlSeries(dt, v, valid, np.full(dt.size, np.nan)),
        AttitudeSeries(at, yaw, rate),
        gps,
        calibration,
    )


def gated_dataset(
    name: str,
    root: Path,
    config: DatasetConfig,
    beams: BeamSeries,
    dvl: DvlSeries,
    attitude: AttitudeSeries,
    gps: GpsSeries | None,
    calibration: str,
    truth: dict[str, Any] | None = None,
    sonar_path: Path | None = None,
) -> Dataset:
    """A dataset of series already read: the gates of :mod:`sonarslam.datasets.gates` and the
    DVL/AHRS overlap check, as :func:`sonarslam.datasets.source.open_dataset` runs them. The
    gates work in place: the DVL's and the AHRS's arrays must be the caller's own to change
    (the dataset holds views of them)."""
    report = SensorReport()
    gates = config.gates
    dvl = gate_dvl(dvl, gates, report, config.noise.dvl_sigma_mps)
    attitude = gate_attitude(attitude, gates, report)
    check_overlap(root, dvl, attitude)
    gated_gps = gate_gps(gps, gates, report) if gps is not None else None
    gate_beams(beams.t_s, gates, report, sonar_path or root, navigation_span_s(dvl, attitude))
    return Dataset(
        name=name,
        root=root,
        config=config,
        beams=beams,
        dvl=dvl,
        attitude=attitude,
        gps=gated_gps,
        truth=truth,
        report=report,
        calibration=calibration,
    )
