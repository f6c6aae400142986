"""The MSIS beam model: raw intensity beams of a mechanically scanned sonar among walls.

Geometry. The logged transducer angle ``a`` is a bearing ``angle_sense * a`` in the right-handed
sonar frame, whose pose in the world is ``wTs = compose(wTb, bTs)`` with ``bTs`` the sonar
mounting. Bin ``i`` (0-based) holds the echo at range ``(i + 1) * bin_size_m``.

Echo. The horizontal beam (width ``beam_width_rad``, taken as the -3 dB full width) is cast as
``n_rays`` sub-rays with Gaussian weights; each sub-ray's first wall hit at range ``r`` and
incidence ``phi`` (angle between the ray and the wall normal) returns

    A = echo_gain * w_ray * cos(phi)**incidence_exponent * fade(phi) * exp(-range_decay_per_m r)

where ``fade`` goes smoothly from 1 at ``incidence_fade_start_rad`` to 0 at
``incidence_cutoff_rad`` (grazing walls return nothing). ``A`` is spread over the bins as a
Gaussian pulse of ``pulse_sigma_bins`` plus a short exponential tail behind the wall (the vertical
beam meeting the wall at longer slant ranges). With a range offset ``d > 0`` (a real head's echo
peaks behind the wall face: pulse length, rough faces) the profile at ``delta = range - r`` is

    (1 + tail_fraction) exp(-(delta - d)^2 / (2 s^2)),  s = d / sqrt(2 ln 2),   delta < d
    exp(-(delta - d)^2 / (2 sigma^2)) + tail_fraction exp(-(delta - d) / tail_m), delta >= d

so it peaks ``d`` behind the wall and its leading edge (half the peak, rising) is on the wall
face. Walls closer than ``dead_zone_m`` return nothing: those bins hold the transducer's ringing,
decaying from ``ringing_level`` at range 0 to a few counts at ``dead_zone_m``. The echo and
the ringing are multiplied by unit-mean Rayleigh speckle (independent per bin); Rayleigh
background noise whose mean grows linearly with range (the head's time-varying gain), sparse
clutter (exponential blobs) and, in a few beams, a false return (a 1-3 bin spike) are added; the
result is rounded and clipped to 0-255.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from sonarslam.datasets.simulator.path import TrueMotion
from sonarslam.datasets.simulator.world import World
from sonarslam.features.geometry import FloatArray, compose
from sonarslam.settings import bounded, check_fields
from sonarslam.sonar.beam import Mounting, SonarBeam, SonarHead, bin_range_m

__all__ = [
    "EchoModel",
    "cast_rays",
    "first_hits",
    "sonar_poses",
    "beam_axis_hits",
    "beam_times",
    "transducer_angles",
    "render_intensities",
    "simulate_msis",
]

_CHUNK_BEAMS = 256


@dataclass(frozen=True)
class EchoModel:
    """Parameters of the echo, noise and dead zone of :func:`render_intensities`.

    Intensities are in the head's 0-255 counts. See the module docstring for the model.

    Attributes
    ----------
    n_rays : int
        Sub-rays the horizontal beam is cast as, with Gaussian weights over its -3 dB width.
    echo_gain : float
        Amplitude of a wall's echo at normal incidence and range 0 (counts), before the
        weights, the incidence and the range decay.
    incidence_exponent : float
        The echo falls as ``cos(phi) ** incidence_exponent`` with the incidence ``phi``.
    incidence_fade_start_rad, incidence_cutoff_rad : float
        The echo fades smoothly from full at the first incidence to none at the second (rad,
        in ``(0, pi/2]``, the first smaller): grazing walls return nothing.
    range_decay_per_m : float
        The echo falls as ``exp(-range_decay_per_m * r)`` with range ``r`` (1/m).
    pulse_sigma_bins : float
        Standard deviation of the echo's Gaussian pulse along the beam (bins).
    tail_m, tail_fraction : float
        The exponential tail behind the wall: its length (m; a world's own wall band replaces
        it) and its height relative to the pulse's peak.
    speckle : bool
        Multiply the echo and the ringing by unit-mean Rayleigh speckle, independent per bin.
    background_near, background_far : float
        Mean of the Rayleigh background noise at range 0 and at the head's maximum range
        (counts), linear in between.
    clutter_prob_per_bin, clutter_mean : float
        Probability that a bin holds clutter, and the clutter's mean (counts, exponential).
    false_return_prob_per_beam : float
        Probability that a beam holds one false return, a spike of 1-3 bins at a uniform range.
    false_return_min, false_return_max : float
        Its height is uniform in this range (counts).
    dead_zone_m : float
        Walls nearer than this return nothing (m); its bins hold the transducer's ringing.
    ringing_level : float
        The ringing at range 0 (counts), decaying as ``exp(-4 r / dead_zone_m)``.
    """

    n_rays: int = bounded(9, 1, 10_000)
    echo_gain: float = 300.0
    incidence_exponent: float = 2.0
    incidence_fade_start_rad: float = bounded(
        float(np.deg2rad(60.0)), 0.0, np.pi / 2, low_open=True, high_open=True
    )
    incidence_cutoff_rad: float = bounded(float(np.deg2rad(70.0)), 0.0, np.pi / 2, low_open=True)
    range_decay_per_m: float = 0.01
    pulse_sigma_bins: float = 0.6
    tail_m: float = 0.15
    tail_fraction: float = 0.3
    speckle: bool = True
    background_near: float = 4.0
    background_far: float = 18.0
    clutter_prob_per_bin: float = 0.002
    clutter_mean: float = 20.0
    false_return_prob_per_beam: float = 0.02
    false_return_min: float = 80.0
    false_return_max: float = 255.0
    dead_zone_m: float = bounded(1.0, 0.0, math.inf)
    ringing_level: float = 180.0

    def __post_init__(self) -> None:
        check_fields(self)
        if not self.incidence_fade_start_rad < self.incidence_cutoff_rad:
            raise ValueError(
                "incidence_fade_start_rad must be < incidence_cutoff_rad, got"
                f" {self.incidence_fade_start_rad} >= {self.incidence_cutoff_rad}"
            )


def cast_rays(
    walls_m: FloatArray, origins_m: npt.ArrayLike, angles_rad: npt.ArrayLike
) -> tuple[FloatArray, FloatArray]:
    """First wall hit of rays, all walls at once.

    Parameters
    ----------
    walls_m : ndarray, shape (S, 2, 2)
        Wall segments (world, m).
    origins_m : array_like, shape (B, 2)
        Ray origins (world, m).
    angles_rad : array_like, shape (B, R)
        Ray directions, counter-clockwise from the world x axis (rad); R rays per origin.

    Returns
    -------
    range_m : ndarray, shape (B, R)
        Distance to the first wall (m); NaN when the ray meets none.
    incidence_rad : ndarray, shape (B, R)
        Angle between the ray and the wall normal, in ``[0, pi/2]`` (rad); NaN with the range.
    """
    r, inc, _ = first_hits(walls_m, origins_m, angles_rad)
    return r, inc


def first_hits(
    walls_m: FloatArray, origins_m: npt.ArrayLike, angles_rad: npt.ArrayLike
) -> tuple[FloatArray, FloatArray, npt.NDArray[np.intp]]:
    """:func:`cast_rays` with the index of the wall each ray meets first (shape (B, R);
    meaningless where the range is NaN)."""
    o = np.asarray(origins_m, dtype=np.float64)
    ang = np.asarray(angles_rad, dtype=np.float64)
    dx, dy = np.cos(ang)[..., None], np.sin(ang)[..., None]  # (B, R, 1)
    a = walls_m[:, 0]
    e = walls_m[:, 1] - a  # (S, 2)
    ex, ey = e[:, 0], e[:, 1]
    ao = a[None] - o[:, None]  # (B, S, 2)
    aox, aoy = ao[:, None, :, 0], ao[:, None, :, 1]  # (B, 1, S)
    denom = dx * ey - dy * ex  # d x e, (B, R, S)
    ok = np.abs(denom) > 1e-12
    safe = np.where(ok, denom, 1.0)
    t = (aox * ey - aoy * ex) / safe
    u = (aox * dy - aoy * dx) / safe
    hit = ok & (t > 1e-9) & (u >= 0.0) & (u <= 1.0)
    t = np.where(hit, t, np.inf)
    j = np.argmin(t, axis=-1)
    r = np.take_along_axis(t, j[..., None], axis=-1)[..., 0]
    d = np.abs(np.take_along_axis(denom, j[..., None], axis=-1)[..., 0])
    cos_inc = np.clip(d / np.linalg.norm(e, axis=1)[j], 0.0, 1.0)
    none = ~np.isfinite(r)
    return np.where(none, np.nan, r), np.where(none, np.nan, np.arccos(cos_inc)), j


def sonar_poses(wTb: npt.ArrayLike, mounting: Mounting) -> FloatArray:
    """Sonar frame poses ``wTs = wTb * bTs``, shape ``(B, 3)``."""
    return compose(np.atleast_2d(np.asarray(wTb, dtype=np.float64)), mounting.as_pose())


def beam_axis_hits(
    world: World,
    head: SonarHead,
    mounting: Mounting,
    wTb: npt.ArrayLike,
    transducer_angle_rad: npt.ArrayLike,
) -> tuple[FloatArray, FloatArray]:
    """True range and incidence of the first wall along each beam's axis (pure geometry).

    Parameters
    ----------
    world : World
    head : SonarHead
        Gives the angle sense.
    mounting : Mounting
        Sonar mounting ``bTs``.
    wTb : array_like, shape (B, 3)
        True body pose at each beam time.
    transducer_angle_rad : array_like, shape (B,)
        Logged transducer angles (rad).

    Returns
    -------
    range_m : ndarray, shape (B,)
        Range from the sonar to the wall (m), NaN if the axis meets no wall; not limited to the
        head's range.
    incidence_rad : ndarray, shape (B,)
        Angle between the axis and the wall normal (rad), NaN with the range.
    """
    wTs = sonar_poses(wTb, mounting)
    bearing = head.bearing_rad(np.atleast_1d(transducer_angle_rad))
    r, inc = cast_rays(world.walls_m, wTs[:, :2], (wTs[:, 2] + bearing)[:, None])
    return r[:, 0], inc[:, 0]


def beam_times(
    n_beams: int, rate_hz: float, t0_s: float, rng: np.random.Generator, jitter_s: float = 0.002
) -> FloatArray:
    """Beam times ``t0 + (k + 0.5) / rate`` with uniform jitter, rounded to the ms (Unix s).

    Parameters
    ----------
    n_beams : int
    rate_hz : float
        Beam rate (Hz), 14.7 for the marina's Miniking.
    t0_s : float
        Start of the run (Unix s).
    rng : numpy.random.Generator
    jitter_s : float
        Half-width of the uniform jitter (s); must be well below ``1 / rate_hz``.

    Returns
    -------
    ndarray, shape (n_beams,)
        Strictly increasing times, exact multiples of 1 ms (as ``write_is_log`` writes them).
    """
    k = np.arange(n_beams, dtype=np.float64)
    t = t0_s + (k + 0.5) / rate_hz + rng.uniform(-jitter_s, jitter_s, n_beams)
    return np.round(t * 1000.0) / 1000.0


def transducer_angles(
    n_beams: int,
    step_rad: float,
    start_rad: float = 0.0,
    sector_rad: float | None = None,
) -> FloatArray:
    """Logged head angles of consecutive beams, rounded to 1e-6 rad (as the log writes them).

    Parameters
    ----------
    n_beams : int
    step_rad : float
        Mechanical step (rad).
    start_rad : float
        Angle of the first beam; for a sector scan, the sector's first edge (rad).
    sector_rad : float or None
        None: continuous 360 deg rotation, angles wrapped to ``[0, 2 pi)``. Otherwise the head
        sweeps back and forth over ``[start_rad, start_rad + sector_rad]``.

    Returns
    -------
    ndarray, shape (n_beams,)
    """
    k = np.arange(n_beams, dtype=np.float64)
    if sector_rad is None:
        a = np.mod(start_rad + k * step_rad, 2.0 * np.pi)
    else:
        n_side = max(int(round(sector_rad / step_rad)), 1)
        phase = np.mod(np.arange(n_beams), 2 * n_side)
        a = start_rad + step_rad * np.where(phase <= n_side, phase, 2 * n_side - phase)
    return np.mod(np.round(a, 6), 2.0 * np.pi)


def render_intensities(
    world: World,
    head: SonarHead,
    mounting: Mounting,
    wTb: npt.ArrayLike,
    transducer_angle_rad: npt.ArrayLike,
    rng: np.random.Generator,
    echo: EchoModel | None = None,
    range_offset_m: float = 0.0,
    range_scale: float = 1.0,
) -> npt.NDArray[np.uint8]:
    """Raw intensities of beams (see the module docstring for the model).

    Parameters
    ----------
    world : World
    head : SonarHead
    mounting : Mounting
        Sonar mounting ``bTs``.
    wTb : array_like, shape (B, 3)
        True body pose at each beam time.
    transducer_angle_rad : array_like, shape (B,)
        Logged transducer angle of each beam (rad).
    rng : numpy.random.Generator
        Source of all noise; the same draws for the same inputs.
    echo : EchoModel, optional
    range_offset_m : float
        How far behind the wall face the echo peaks (m, >= 0; see the module docstring).
    range_scale : float
        An echo from true range ``r`` is logged at ``range_scale * r`` (a sound-speed error).

    Returns
    -------
    ndarray of uint8, shape (B, n_bins)
    """
    if range_offset_m < 0.0:
        raise ValueError(f"range_offset_m must be >= 0, got {range_offset_m}")
    echo = echo if echo is not None else EchoModel()
    poses = np.atleast_2d(np.asarray(wTb, dtype=np.float64))
    angles = np.atleast_1d(np.asarray(transducer_angle_rad, dtype=np.float64))
    out = np.empty((poses.shape[0], head.n_bins), dtype=np.uint8)
    for i in range(0, poses.shape[0], _CHUNK_BEAMS):
        sl = slice(i, i + _CHUNK_BEAMS)
        out[sl] = _render_chunk(
            world, head, mounting, poses[sl], angles[sl], rng, echo, range_offset_m, range_scale
        )
    return out


def _walls_near(walls_m: FloatArray, origins_m: FloatArray, reach_m: float) -> npt.NDArray[np.intp]:
    """Indices of the walls that may lie within ``reach_m`` of any of the origins (m): those
    within reach of the origins' bounding box (a ray meets no other wall inside the range)."""
    lo, hi = origins_m.min(axis=0), origins_m.max(axis=0)
    centre, half_diag = (lo + hi) / 2.0, float(np.linalg.norm(hi - lo)) / 2.0
    a = walls_m[:, 0]
    ab = walls_m[:, 1] - a
    u = np.clip(
        np.sum((centre - a) * ab, axis=1) / np.maximum(np.sum(ab * ab, axis=1), 1e-12), 0, 1
    )
    dist = np.linalg.norm(a + u[:, None] * ab - centre, axis=1)
    near = np.flatnonzero(dist <= reach_m + half_diag)
    return near if near.size else np.arange(walls_m.shape[0])


#: Below this exponent ``np.exp`` gives exactly 0.0 (it underflows below -745.14): the profiles
#: take 0.0 there without evaluating it, the same values at a fraction of the cost (most bins
#: of a ray lie far from its wall).
_EXP_ZERO_BELOW = -750.0


def _exp_or_zero(exponent: FloatArray, needed: npt.NDArray[np.bool_] | None = None) -> FloatArray:
    """``np.exp(exponent)`` where ``needed`` (default: everywhere), evaluated only where it is
    not exactly 0.0 (the same values there); 0.0 where not needed."""
    live = ~(exponent < _EXP_ZERO_BELOW)  # NaN kept: np.exp gives it as before
    if needed is not None:
        live &= needed
    out = np.zeros(exponent.shape)
    np.exp(exponent, out=out, where=live)
    return out


def _offset_profile(
    delta_m: FloatArray,
    offset_m: float,
    sigma_m: float,
    echo: EchoModel,
    tail_m: float | FloatArray,
) -> FloatArray:
    """The echo profile that peaks ``offset_m`` behind the wall face, with its leading edge (half
    the peak) on it (module docstring); ``delta_m`` is bin range minus wall range (m), ``tail_m``
    the length of the tail (m, or per ray, broadcast against ``delta_m``)."""
    peak = 1.0 + echo.tail_fraction
    rise_sigma_m = offset_m / np.sqrt(2.0 * np.log(2.0))
    after = delta_m - offset_m
    before = after < 0.0  # the rising edge; the fall elsewhere (each computed only where used)
    behind = np.maximum(after, 0.0)
    fall = _exp_or_zero(-0.5 * (behind / sigma_m) ** 2, ~before)
    fall += echo.tail_fraction * _exp_or_zero(-behind / tail_m, ~before)
    rise = peak * _exp_or_zero(-0.5 * (np.minimum(after, 0.0) / rise_sigma_m) ** 2, before)
    return np.asarray(np.where(before, rise, fall))


def _render_chunk(
    world: World,
    head: SonarHead,
    mounting: Mounting,
    wTb: FloatArray,
    angles: FloatArray,
    rng: np.random.Generator,
    echo: EchoModel,
    range_offset_m: float,
    range_scale: float = 1.0,
) -> npt.NDArray[np.uint8]:
    n_beams, n_bins = wTb.shape[0], head.n_bins
    r_bins = bin_range_m(np.arange(n_bins), head.bin_size_m)  # (N,) raw: the echo's own range
    wTs = sonar_poses(wTb, mounting)
    half = head.beam_width_rad / 2.0
    offsets = np.linspace(-half, half, echo.n_rays) if echo.n_rays > 1 else np.zeros(1)
    weights = np.exp(-0.5 * (offsets / (head.beam_width_rad / 2.3548)) ** 2)
    weights /= weights.sum()
    ray_angles = (wTs[:, 2] + head.bearing_rad(angles))[:, None] + offsets[None, :]
    near = _walls_near(world.walls_m, wTs[:, :2], head.range_max_m + 2.0 * head.bin_size_m)
    r, inc, j = first_hits(world.walls_m[near], wTs[:, :2], ray_angles)  # (B, R)
    hit_wall = near[j]
    if range_scale != 1.0:
        r = r * range_scale  # where the sonar logs the echo

    fade_span = echo.incidence_cutoff_rad - echo.incidence_fade_start_rad
    fade = np.clip((echo.incidence_cutoff_rad - inc) / fade_span, 0.0, 1.0)
    fade = fade * fade * (3.0 - 2.0 * fade)  # smoothstep
    amp = (
        echo.echo_gain
        * weights[None, :]
        * np.cos(inc) ** echo.incidence_exponent
        * fade
        * np.exp(-echo.range_decay_per_m * r)
    )
    if world.wall_gain is not None:  # each wall's own echo strength
        amp = amp * world.wall_gain[hit_wall]
    visible = np.isfinite(r) & (r >= echo.dead_zone_m) & (r <= head.range_max_m + head.bin_size_m)
    amp = np.where(visible, amp, 0.0)
    r = np.where(visible, r, -1e3)

    delta = r_bins[None, None, :] - r[..., None]  # (B, R, N), m
    sigma_m = echo.pulse_sigma_bins * head.bin_size_m
    # each wall's band thickness: the length of its echo's tail
    tail_m: float | FloatArray = (
        echo.tail_m if world.wall_band_m is None else world.wall_band_m[hit_wall][..., None]
    )
    if range_offset_m > 0.0:
        profile = _offset_profile(delta, range_offset_m, sigma_m, echo, tail_m)
    else:
        profile = _exp_or_zero(-0.5 * (delta / sigma_m) ** 2)
        if echo.tail_fraction > 0.0:
            behind = np.maximum(delta, 0.0)
            tail = delta > 0.0
            profile += np.where(
                tail, echo.tail_fraction * _exp_or_zero(-behind / tail_m, tail), 0.0
            )
    signal = np.einsum("brn,br->bn", profile, amp)

    if echo.dead_zone_m > 0.0:
        ringing = echo.ringing_level * np.exp(-4.0 * r_bins / echo.dead_zone_m)
        signal += ringing[None, :]
    if echo.speckle:
        signal *= rng.rayleigh(np.sqrt(2.0 / np.pi), size=(n_beams, n_bins))
    bg_mean = echo.background_near + (echo.background_far - echo.background_near) * (
        r_bins / head.range_max_m
    )
    signal += rng.rayleigh(1.0, size=(n_beams, n_bins)) * (bg_mean / np.sqrt(np.pi / 2.0))
    clutter = rng.random((n_beams, n_bins)) < echo.clutter_prob_per_bin
    signal += np.where(clutter, rng.exponential(echo.clutter_mean, size=(n_beams, n_bins)), 0.0)
    spiky = np.flatnonzero(rng.random(n_beams) < echo.false_return_prob_per_beam)
    for b in spiky:
        start = int(rng.integers(n_bins))
        width = int(rng.integers(1, 4))
        signal[b, start : start + width] += rng.uniform(
            echo.false_return_min, echo.false_return_max
        )
    return np.clip(np.rint(signal), 0, 255).astype(np.uint8)


def simulate_msis(
    world: World,
    head: SonarHead,
    mounting: Mounting,
    trajectory: TrueMotion,
    rng: np.random.Generator,
    rate_hz: float = 14.7,
    start_rad: float = 0.0,
    sector_rad: float | None = None,
    echo: EchoModel | None = None,
    range_offset_m: float = 0.0,
    range_scale: float = 1.0,
) -> list[SonarBeam]:
    """All beams of a run: times, head angles and raw intensities.

    The head advances by ``head.step_rad`` every beam; beams come at ``rate_hz`` over the whole
    trajectory. Each beam is rendered at the true body pose at its time.

    Parameters
    ----------
    world, head, mounting, trajectory
        The scene, the sonar head, its mounting ``bTs`` and the true motion.
    rng : numpy.random.Generator
        Source of timing jitter and echo noise.
    rate_hz : float
        Beam rate (Hz).
    start_rad, sector_rad : float
        See :func:`transducer_angles`.
    echo : EchoModel, optional
    range_offset_m : float
        How far behind the wall face the echo peaks (m; see the module docstring).
    range_scale : float
        An echo from true range ``r`` is logged at ``range_scale * r``.

    Returns
    -------
    list of SonarBeam
        Raw beams (``thresholded=False``), in time order.
    """
    t0 = float(trajectory.t_s[0])
    n = int(np.floor((trajectory.duration_s - 0.01) * rate_hz))
    t = beam_times(n, rate_hz, t0, rng)
    a = transducer_angles(n, head.step_rad, start_rad, sector_rad)
    intensities = render_intensities(
        world, head, mounting, trajectory.poses(t), a, rng, echo, range_offset_m, range_scale
    )
    return [
        SonarBeam(t=float(t[k]), transducer_angle_rad=float(a[k]), intensities=intensities[k])
        for k in range(n)
    ]
