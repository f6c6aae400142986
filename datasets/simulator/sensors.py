"""Navigation sensors of the simulated vehicle: DVL, AHRS (MTi) and GPS, with noise.

Conventions (the marina's logs):

* DVL: bottom-track velocity of the DVL in its own frame (x, y right-handed, z up), the body
  velocity rotated by the inverse of the DVL mounting yaw (plus the lever-arm term
  ``omega x r`` when the DVL is off the body origin). Its compass is the heading of the DVL x
  axis, clockwise from North, in ``[0, 360)`` deg.
* AHRS: the MTi frame is x forward, y right, z DOWN relative to the AHRS mounting, so its yaw is a
  heading growing clockwise from North (``90 deg - yaw_ccw``) in ``[-180, 180)`` deg, its
  ``rate_z`` is minus the counter-clockwise yaw rate, and at rest it measures ``acc_z = -g``.
* GPS: fixes of the body origin (the antenna), local East-North metres around the geodetic origin,
  converted to latitude and longitude with ``pymap3d.enu2geodetic``.

Beside the white noise (:class:`SensorNoise`), a scenario may give the systematic errors that make
a real vehicle's dead reckoning drift (:class:`DriftErrors`): a DVL scale factor and bias, and a
random walk of the AHRS heading on top of its constant bias and deviation.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import pymap3d

from sonarslam.datasets.simulator.path import TrueMotion
from sonarslam.features.geometry import FloatArray, wrap_angle
from sonarslam.settings import bounded, check_fields
from sonarslam.sonar.beam import Mounting

__all__ = [
    "SensorNoise",
    "DriftErrors",
    "GeodeticOrigin",
    "MARINA_ORIGIN",
    "DvlSamples",
    "AhrsSamples",
    "GpsSamples",
    "sample_times",
    "heading_random_walk",
    "simulate_dvl",
    "simulate_ahrs",
    "simulate_gps",
]

GRAVITY_MPS2 = 9.81


@dataclass(frozen=True)
class SensorNoise:
    """Noise of the simulated navigation sensors (1-sigma unless stated).

    Attributes
    ----------
    dvl_sigma_mps : float
        White noise on each bottom-track velocity component (m/s).
    dvl_dropout_rate_per_s : float
        Rate of bottom-lock losses (1/s); each lasts a uniform time in
        ``[dvl_dropout_min_s, dvl_dropout_max_s]``, during which ``bottomVelStatus`` is 0.
    dvl_compass_sigma_deg : float
        White noise of the DVL's own compass (deg).
    dvl_compass_deviation_deg : tuple of float
        ``(B, C)``: the DVL compass reads ``B sin(yaw) + C cos(yaw)`` (deg) off, ``yaw`` the
        DVL frame's yaw, as a compass deflected by the vehicle's own field (hard iron)
        (docs/research/calibration.md gives the marina's).
    ahrs_sigma_deg : float
        White noise of the AHRS heading (deg).
    ahrs_bias_deg : float
        Constant bias added to the AHRS clockwise heading (deg); the AHRS yaw counter-clockwise
        from East is therefore ``true - bias``.
    ahrs_rate_sigma_rad_per_s : float
        White noise of the AHRS rates (rad/s).
    ahrs_deviation_deg : tuple of float
        ``(B, C)``: the AHRS yaw (counter-clockwise) reads ``B sin(psi) + C cos(psi)`` (deg)
        off, ``psi`` the true body yaw, as a compass deflected by the vehicle (hard iron).
    ahrs_gyro_bias_rad_per_s : float
        Constant bias of the AHRS yaw rate (rad/s, counter-clockwise) (docs/research/calibration.md
        gives the marina MTi's).
    ahrs_acc_sigma_mps2 : float
        White noise of the AHRS accelerations (m/s^2).
    ahrs_attitude_sigma_deg : float
        White noise of roll and pitch (deg).
    gps_sigma_m : float
        White noise of each GPS position component, East and North (m).
    dvl_degraded_from_s : float or None
        From this many seconds after the start, the DVL's white noise is
        ``dvl_degraded_sigma_mps`` instead (as the marina's DVL degrades at the end of its run:
        docs/research/results.md); None: never.
    dvl_degraded_sigma_mps : float
        The DVL's white noise once degraded (m/s).
    """

    dvl_sigma_mps: float = 0.02
    dvl_dropout_rate_per_s: float = 1.0 / 120.0
    dvl_dropout_min_s: float = 3.0
    dvl_dropout_max_s: float = 10.0
    dvl_compass_sigma_deg: float = 3.0
    dvl_compass_deviation_deg: tuple[float, float] = (0.0, 0.0)
    ahrs_sigma_deg: float = 0.5
    ahrs_bias_deg: float = 2.0
    ahrs_rate_sigma_rad_per_s: float = 0.002
    ahrs_gyro_bias_rad_per_s: float = 0.0
    ahrs_deviation_deg: tuple[float, float] = (0.0, 0.0)
    ahrs_acc_sigma_mps2: float = 0.02
    ahrs_attitude_sigma_deg: float = 0.1
    gps_sigma_m: float = 0.7
    dvl_degraded_from_s: float | None = None
    dvl_degraded_sigma_mps: float = 0.3

    def __post_init__(self) -> None:
        if self.dvl_dropout_min_s > self.dvl_dropout_max_s:
            raise ValueError("SensorNoise.dvl_dropout_min_s must not exceed dvl_dropout_max_s")


@dataclass(frozen=True)
class DriftErrors:
    """Systematic sensor errors of a real vehicle: what makes its dead reckoning drift.

    None of them is in the ``sonarslam.toml`` the simulator writes (the estimators are not told);
    ``truth.json`` holds them (``errors``) with the realised heading walk.

    Attributes
    ----------
    dvl_scale_factor : float
        ``k``: the DVL measures ``(1 + k) v + b`` (plus its white noise) for the true velocity
        ``v`` of its point in its own frame; a sound-speed or beam-angle error, 0.2-2 % on real
        DVLs.
    dvl_bias_mps : tuple of float
        ``b = (b_x, b_y)``: constant bias of the DVL velocity in the DVL frame (m/s).
    ahrs_heading_walk_deg_per_sqrt_s : float
        ``sigma``: a random walk added to the AHRS heading (:func:`heading_random_walk`), on top
        of its constant bias and deviation: the increment over ``dt`` is ``N(0, sigma^2 dt)``
        (deg/sqrt(s)), zero at the first AHRS sample.
    echo_range_offset_m : float
        How far behind the wall face the sonar's echo peaks (m); its leading edge (half the
        peak, rising) stays on the wall face (:mod:`sonarslam.datasets.simulator.msis`).
    sonar_range_scale : float
        ``s``: the sonar logs an echo from true range ``r`` at ``s * r`` (a sound-speed error;
        1: none).
    ahrs_heading_field_deg : float
        RMS of a place-dependent disturbance of the AHRS heading (deg, a magnetic field bent by
        steel walls and hulls): :func:`heading_field` at the vehicle's position, added to the
        walk; 0: none.
    ahrs_heading_field_wavelength_m : float
        Its wavelength (m).
    """

    dvl_scale_factor: float = bounded(0.0, -0.5, 0.5, low_open=True, high_open=True)
    dvl_bias_mps: tuple[float, float] = (0.0, 0.0)
    ahrs_heading_walk_deg_per_sqrt_s: float = bounded(0.0, 0.0, math.inf)
    echo_range_offset_m: float = bounded(0.0, 0.0, math.inf)
    sonar_range_scale: float = bounded(1.0, 0.5, 1.5, low_open=True, high_open=True)
    ahrs_heading_field_deg: float = bounded(0.0, 0.0, math.inf)
    ahrs_heading_field_wavelength_m: float = bounded(80.0, 0.0, math.inf, low_open=True)

    def __post_init__(self) -> None:
        check_fields(self)


@dataclass(frozen=True)
class GeodeticOrigin:
    """Geodetic point of the world origin (WGS84): latitude, longitude (deg), height (m)."""

    lat_deg: float
    lon_deg: float
    h_m: float = 0.0


#: The abandoned marina's first DGPS fix, 42 deg 12.225 min N, 3 deg 6.2832 min E.
MARINA_ORIGIN = GeodeticOrigin(lat_deg=42.0 + 12.225 / 60.0, lon_deg=3.0 + 6.2832 / 60.0)


@dataclass(frozen=True, eq=False)
class DvlSamples:
    """Simulated DVL output.

    Attributes
    ----------
    t_s : ndarray, shape (N,)
        Unix times (s), multiples of 1 ms.
    v_dvl_mps : ndarray, shape (N, 3)
        Measured bottom-track velocity in the DVL frame (x, y, z up) (m/s); meaningless where
        ``valid`` is False.
    valid : ndarray of bool, shape (N,)
        Bottom lock.
    compass_deg : ndarray, shape (N,)
        DVL compass: heading of the DVL x axis, clockwise from North, in ``[0, 360)`` (deg).
    altitude_m : ndarray, shape (N,)
        Range to the bottom (m), for the log's ``rangeBottom`` columns.
    dropouts_s : ndarray, shape (K, 2)
        ``[start, end]`` of each bottom-lock loss (Unix s).
    """

    t_s: FloatArray = field(repr=False)
    v_dvl_mps: FloatArray = field(repr=False)
    valid: np.ndarray = field(repr=False)
    compass_deg: FloatArray = field(repr=False)
    altitude_m: FloatArray = field(repr=False)
    dropouts_s: FloatArray = field(repr=False)


@dataclass(frozen=True, eq=False)
class AhrsSamples:
    """Simulated MTi output (frame x forward, y right, z down; see the module docstring).

    Attributes
    ----------
    t_s : ndarray, shape (N,)
        Unix times (s).
    roll_deg, pitch_deg : ndarray, shape (N,)
    heading_deg : ndarray, shape (N,)
        The log's ``yaw``: heading of the AHRS frame clockwise from North, ``[-180, 180)`` (deg).
    rate_rad_per_s : ndarray, shape (N, 3)
        Angular rates about the MTi x, y, z axes (rad/s); ``rate_z`` is positive clockwise.
    acc_mps2 : ndarray, shape (N, 3)
        Specific force along the MTi axes (m/s^2); ``acc_z`` is about ``-9.81``.
    heading_walk_deg : ndarray, shape (N,) or None
        The slowly varying error in ``heading_deg`` (deg, clockwise like the heading): the random
        walk plus the place-dependent field (:class:`DriftErrors`); None without either.
    """

    t_s: FloatArray = field(repr=False)
    roll_deg: FloatArray = field(repr=False)
    pitch_deg: FloatArray = field(repr=False)
    heading_deg: FloatArray = field(repr=False)
    rate_rad_per_s: FloatArray = field(repr=False)
    acc_mps2: FloatArray = field(repr=False)
    heading_walk_deg: FloatArray | None = field(default=None, repr=False)


@dataclass(frozen=True, eq=False)
class GpsSamples:
    """Simulated GPS fixes.

    Attributes
    ----------
    t_s : ndarray, shape (N,)
        Unix times (s).
    enu_m : ndarray, shape (N, 2)
        Measured East, North in the world frame (m), noise included.
    lat_deg, lon_deg : ndarray, shape (N,)
        The same positions as WGS84 latitude and longitude (deg).
    course_deg : ndarray, shape (N,)
        True course over ground, clockwise from North, ``[0, 360)`` (deg).
    speed_mps : ndarray, shape (N,)
        Speed over ground (m/s).
    """

    t_s: FloatArray = field(repr=False)
    enu_m: FloatArray = field(repr=False)
    lat_deg: FloatArray = field(repr=False)
    lon_deg: FloatArray = field(repr=False)
    course_deg: FloatArray = field(repr=False)
    speed_mps: FloatArray = field(repr=False)


def sample_times(
    trajectory: TrueMotion,
    rate_hz: float,
    offset_s: float,
    rng: np.random.Generator,
    jitter_s: float,
) -> FloatArray:
    """Sensor times ``t0 + offset + k / rate`` with uniform jitter, rounded to 1 ms (Unix s).

    Only times inside the trajectory are kept; they are strictly increasing when
    ``2 jitter_s < 1 / rate_hz``.
    """
    t0, t1 = float(trajectory.t_s[0]), float(trajectory.t_s[-1])
    n = int(np.floor((t1 - t0 - offset_s - jitter_s) * rate_hz)) + 1
    t = t0 + offset_s + np.arange(max(n, 0)) / rate_hz
    t = t + rng.uniform(-jitter_s, jitter_s, t.size)
    t = np.round(t * 1000.0) / 1000.0
    return t[(t >= t0) & (t <= t1)]


def heading_random_walk(
    t_s: FloatArray, sigma_deg_per_sqrt_s: float, rng: np.random.Generator
) -> FloatArray:
    """A Wiener process of intensity ``sigma_deg_per_sqrt_s`` (deg/sqrt(s)) at the increasing times
    ``t_s`` (s, shape (N,)): zero at the first, increments ``N(0, sigma^2 (t_k - t_{k-1}))``;
    shape (N,), deg."""
    t = np.asarray(t_s, dtype=np.float64)
    if t.size == 0:
        return np.zeros(0)
    steps = sigma_deg_per_sqrt_s * np.sqrt(np.diff(t)) * rng.normal(0.0, 1.0, t.size - 1)
    return np.concatenate([[0.0], np.cumsum(steps)])


#: Plane waves summed by :func:`heading_field`.
HEADING_FIELD_WAVES = 4


def heading_field(
    xy_m: FloatArray, rms_deg: float, wavelength_m: float, rng: np.random.Generator
) -> FloatArray:
    """A smooth random field of heading disturbance over the plane, at the points ``xy_m``
    (m, shape (N, 2)): ``rms * sqrt(2 / W) * sum_i cos(2 pi u_i . p / wavelength + phi_i)``
    over :data:`HEADING_FIELD_WAVES` waves of random directions ``u_i`` and phases ``phi_i``
    (drawn from ``rng``); RMS ``rms_deg`` over the plane, shape (N,), deg."""
    a = rng.uniform(0.0, 2.0 * np.pi, HEADING_FIELD_WAVES)
    phi = rng.uniform(0.0, 2.0 * np.pi, HEADING_FIELD_WAVES)
    u = np.column_stack([np.cos(a), np.sin(a)])
    k = 2.0 * np.pi / wavelength_m
    waves = np.cos(k * (np.asarray(xy_m, dtype=np.float64) @ u.T) + phi)
    return np.asarray(rms_deg * np.sqrt(2.0 / HEADING_FIELD_WAVES) * waves.sum(axis=1))


def _dropouts(t0_s: float, t1_s: float, noise: SensorNoise, rng: np.random.Generator) -> FloatArray:
    out: list[tuple[float, float]] = []
    if noise.dvl_dropout_rate_per_s <= 0.0:
        return np.zeros((0, 2))
    t = t0_s + rng.exponential(1.0 / noise.dvl_dropout_rate_per_s)
    while t < t1_s:
        length = rng.uniform(noise.dvl_dropout_min_s, noise.dvl_dropout_max_s)
        out.append((t, t + length))
        t += length + rng.exponential(1.0 / noise.dvl_dropout_rate_per_s)
    return np.array(out, dtype=np.float64).reshape(-1, 2)


def simulate_dvl(
    trajectory: TrueMotion,
    mounting: Mounting,
    noise: SensorNoise,
    rng: np.random.Generator,
    rate_hz: float = 1.5,
    altitude_m: float = 1.85,
    errors: DriftErrors | None = None,
) -> DvlSamples:
    """Bottom-track velocities of a DVL mounted at ``mounting`` (``bTd``).

    The measured velocity in the DVL frame is ``(1 + k) v + b + n``: ``v`` the true velocity of
    the DVL point, ``k`` and ``b`` the scale factor and bias of ``errors`` (none without),
    ``n`` the white noise of ``noise``.

    Parameters
    ----------
    trajectory : TrueMotion
        True motion.
    mounting : Mounting
        DVL frame in the body frame.
    noise : SensorNoise
    rng : numpy.random.Generator
    rate_hz : float
        Ping rate (Hz), about 1.5 for the marina's Argonaut.
    altitude_m : float
        Height of the DVL over the bottom (m).
    errors : DriftErrors, optional
        Scale factor and bias (its other fields are not the DVL's).

    Returns
    -------
    DvlSamples
    """
    t = sample_times(trajectory, rate_hz, 0.3, rng, 0.01)
    v_b = trajectory.velocity_body_mps(t)
    w = trajectory.yaw_rate_at(t)
    # velocity of the DVL point in the body frame: v + omega x r
    v_point = v_b + np.column_stack([-w * mounting.y_m, w * mounting.x_m])
    c, s = np.cos(mounting.yaw_rad), np.sin(mounting.yaw_rad)
    v_d = np.column_stack(
        [c * v_point[:, 0] + s * v_point[:, 1], -s * v_point[:, 0] + c * v_point[:, 1]]
    )
    if errors is not None:
        v_d = (1.0 + errors.dvl_scale_factor) * v_d + np.asarray(errors.dvl_bias_mps)
    sigma = np.full(t.size, noise.dvl_sigma_mps)
    if noise.dvl_degraded_from_s is not None:
        late = t >= float(trajectory.t_s[0]) + noise.dvl_degraded_from_s
        sigma[late] = noise.dvl_degraded_sigma_mps
    v_meas = np.column_stack([v_d, np.zeros(t.size)]) + sigma[:, None] * rng.normal(
        0.0, 1.0, (t.size, 3)
    )
    dropouts = _dropouts(float(trajectory.t_s[0]), float(trajectory.t_s[-1]), noise, rng)
    lost = np.zeros(t.size, dtype=bool)
    for start, end in dropouts:
        lost |= (t >= start) & (t <= end)
    yaw_dvl = trajectory.poses(t)[:, 2] + mounting.yaw_rad
    b_deg, c_deg = noise.dvl_compass_deviation_deg
    deviation = b_deg * np.sin(yaw_dvl) + c_deg * np.cos(yaw_dvl)
    compass = np.mod(
        90.0
        - np.rad2deg(yaw_dvl)
        + deviation
        + rng.normal(0.0, noise.dvl_compass_sigma_deg, t.size),
        360.0,
    )
    return DvlSamples(
        t_s=t,
        v_dvl_mps=v_meas,
        valid=~lost,
        compass_deg=compass,
        altitude_m=altitude_m + rng.normal(0.0, 0.01, t.size),
        dropouts_s=dropouts,
    )


def simulate_ahrs(
    trajectory: TrueMotion,
    mounting: Mounting,
    noise: SensorNoise,
    rng: np.random.Generator,
    rate_hz: float = 10.0,
    roll_deg: float = 0.5,
    pitch_deg: float = -2.5,
    errors: DriftErrors | None = None,
    walk_rng: np.random.Generator | None = None,
) -> AhrsSamples:
    """MTi output for an AHRS mounted with yaw ``mounting.yaw_rad`` in the body.

    The logged heading (clockwise from North) is the true one plus the constant bias, minus the
    deviation (``noise``), plus the random walk of ``errors`` (:func:`heading_random_walk`),
    plus white noise.

    Parameters
    ----------
    trajectory : TrueMotion
    mounting : Mounting
        AHRS frame in the body frame (only its yaw is used).
    noise : SensorNoise
        White noise and the constant heading bias.
    rng : numpy.random.Generator
    rate_hz : float
        Output rate (Hz).
    roll_deg, pitch_deg : float
        Constant attitude of the vehicle (deg).
    errors : DriftErrors, optional
        Its ``ahrs_heading_walk_deg_per_sqrt_s`` (its other fields are not the AHRS's).
    walk_rng : numpy.random.Generator, optional
        Source of the heading walk (its own stream, so that the walk leaves every other draw
        as it is); required when the walk is on.

    Returns
    -------
    AhrsSamples
    """
    t = sample_times(trajectory, rate_hz, 0.04, rng, 0.003)
    n = t.size
    yaw_ahrs = trajectory.poses(t)[:, 2] + mounting.yaw_rad
    psi = trajectory.poses(t)[:, 2]
    b_deg, c_deg = noise.ahrs_deviation_deg
    heading = 90.0 - np.rad2deg(yaw_ahrs) + noise.ahrs_bias_deg
    heading = heading - (b_deg * np.sin(psi) + c_deg * np.cos(psi))  # yaw CCW = 90 - heading
    walk: FloatArray | None = None
    if errors is not None and errors.ahrs_heading_walk_deg_per_sqrt_s > 0.0:
        if walk_rng is None:
            raise ValueError("simulate_ahrs: a heading random walk needs walk_rng")
        walk = heading_random_walk(t, errors.ahrs_heading_walk_deg_per_sqrt_s, walk_rng)
    if errors is not None and errors.ahrs_heading_field_deg > 0.0:
        if walk_rng is None:
            raise ValueError("simulate_ahrs: a heading field needs walk_rng")
        # drawn after the walk from its stream: the walk of a world without the field is kept
        place = heading_field(
            trajectory.poses(t)[:, :2],
            errors.ahrs_heading_field_deg,
            errors.ahrs_heading_field_wavelength_m,
            walk_rng,
        )
        walk = place if walk is None else walk + place
    if walk is not None:
        heading = heading + walk
    heading = heading + rng.normal(0.0, noise.ahrs_sigma_deg, n)
    heading = np.rad2deg(wrap_angle(np.deg2rad(heading)))
    w = trajectory.yaw_rate_at(t)
    # acceleration of the body in the body frame: dv/dt + omega x v
    dv = np.gradient(trajectory.v_body_mps, trajectory.t_s, axis=0)
    acc_b = (
        np.column_stack([np.interp(t, trajectory.t_s, dv[:, i]) for i in (0, 1)])
        + np.column_stack([-w, w]) * trajectory.velocity_body_mps(t)[:, ::-1]
    )
    c, s = np.cos(mounting.yaw_rad), np.sin(mounting.yaw_rad)
    acc_a = np.column_stack([c * acc_b[:, 0] + s * acc_b[:, 1], -s * acc_b[:, 0] + c * acc_b[:, 1]])
    rate = np.column_stack([np.zeros(n), np.zeros(n), -w - noise.ahrs_gyro_bias_rad_per_s])
    acc = np.column_stack([acc_a[:, 0], -acc_a[:, 1], np.full(n, -GRAVITY_MPS2)])
    return AhrsSamples(
        t_s=t,
        roll_deg=roll_deg + rng.normal(0.0, noise.ahrs_attitude_sigma_deg, n),
        pitch_deg=pitch_deg + rng.normal(0.0, noise.ahrs_attitude_sigma_deg, n),
        heading_deg=heading,
        rate_rad_per_s=rate + rng.normal(0.0, noise.ahrs_rate_sigma_rad_per_s, (n, 3)),
        acc_mps2=acc + rng.normal(0.0, noise.ahrs_acc_sigma_mps2, (n, 3)),
        heading_walk_deg=walk,
    )


def simulate_gps(
    trajectory: TrueMotion,
    origin: GeodeticOrigin,
    noise: SensorNoise,
    rng: np.random.Generator,
    rate_hz: float = 1.0,
) -> GpsSamples:
    """GPS fixes of the body origin, with white noise.

    Parameters
    ----------
    trajectory : TrueMotion
    origin : GeodeticOrigin
        Geodetic point of the world origin.
    noise : SensorNoise
    rng : numpy.random.Generator
    rate_hz : float
        Fix rate (Hz).

    Returns
    -------
    GpsSamples
    """
    t = sample_times(trajectory, rate_hz, 0.9, rng, 0.0)
    xy = trajectory.poses(t)[:, :2]
    enu = xy + rng.normal(0.0, noise.gps_sigma_m, xy.shape)
    lat, lon, _ = pymap3d.enu2geodetic(
        enu[:, 0], enu[:, 1], np.zeros(t.size), origin.lat_deg, origin.lon_deg, origin.h_m
    )
    yaw = trajectory.poses(t)[:, 2]
    v_b = trajectory.velocity_body_mps(t)
    c, s = np.cos(yaw), np.sin(yaw)
    v_w = np.column_stack([c * v_b[:, 0] - s * v_b[:, 1], s * v_b[:, 0] + c * v_b[:, 1]])
    course = np.mod(90.0 - np.rad2deg(np.arctan2(v_w[:, 1], v_w[:, 0])), 360.0)
    return GpsSamples(
        t_s=t,
        enu_m=enu,
        lat_deg=np.asarray(lat, dtype=np.float64),
        lon_deg=np.asarray(lon, dtype=np.float64),
        course_deg=course,
        speed_mps=np.hypot(v_w[:, 0], v_w[:, 1]),
    )
