"""Scenarios (what is simulated) and their in-memory simulation (what the sensors saw, and truth).

A scenario is fully determined by its kind and seed: every random draw comes from
``numpy.random.SeedSequence([seed, kind index])``, spawned into one independent stream per
component (world, path, sonar, DVL, AHRS, GPS, then the drift errors and the heading walk), so the
same seed always gives the same run, bit for bit, and a component's draws never shift another's.

Kinds: ``pool`` (the seed paper's pool test), ``harbour`` (a marina-like survey, 600 s),
``random`` (a free path in a random rectilinear harbour, 600 s), ``drift``
(:func:`~sonarslam.datasets.simulator.world.drift_world`, 1,800 s, with the systematic sensor errors of a
real vehicle, :class:`~sonarslam.datasets.simulator.sensors.DriftErrors`, drawn per seed by
:func:`draw_drift_errors`) and ``drawn`` (1,800 s with the same errors in a harbour and route
drawn per seed, :func:`~sonarslam.datasets.simulator.layout.drawn_world`, and the AHRS's constant heading
bias drawn per seed too). ``harbour`` and ``drift`` are fixed layouts (only the sensors' draws
change with the seed): regression tests and figures; ``drawn`` is the one whose worlds differ.

Seeds from :data:`HELD_BACK_SEED_MIN` on are held back: nothing is tuned on them, and the
figures on the simulator that count (docs/simulator.md) come from them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np

from sonarslam.datasets.config import DatasetConfig, NoiseConfig
from sonarslam.datasets.records import Attitude, DvlVelocity, GpsFix, Record
from sonarslam.datasets.simulator.layout import drawn_world
from sonarslam.datasets.simulator.msis import EchoModel, beam_axis_hits, simulate_msis
from sonarslam.datasets.simulator.path import T0_S, TrueMotion, free_path, stationary, survey
from sonarslam.datasets.simulator.sensors import (
    MARINA_ORIGIN,
    AhrsSamples,
    DriftErrors,
    DvlSamples,
    GeodeticOrigin,
    GpsSamples,
    SensorNoise,
    simulate_ahrs,
    simulate_dvl,
    simulate_gps,
)
from sonarslam.datasets.simulator.world import (
    World,
    drift_world,
    harbour_world,
    pool_world,
    random_harbour_world,
)
from sonarslam.features.geometry import FloatArray, compose, inverse, wrap_angle
from sonarslam.settings import Range, check_fields
from sonarslam.sonar.beam import Mounting, SonarBeam, SonarHead

__all__ = [
    "KINDS",
    "HELD_BACK_SEED_MIN",
    "AHRS_BIAS_SIGMA_DEG",
    "MARINA_HEAD",
    "POOL_HEAD",
    "SONAR_MOUNTING",
    "DVL_MOUNTING",
    "AHRS_MOUNTING",
    "Scenario",
    "Simulation",
    "DRIFT_DVL_SCALE_RANGE",
    "DRIFT_DVL_SCALE_SIGMA",
    "DRIFT_DVL_BIAS_MAX_MPS",
    "DRIFT_HEADING_WALK_DEG_PER_SQRT_S",
    "DRIFT_ECHO_RANGE_OFFSET_M",
    "DRAWN_RANGE_SCALE_ERROR",
    "DRAWN_MOUNT_OFFSET_MAX",
    "DRAWN_HEADING_FIELD_DEG",
    "DRAWN_HEADING_FIELD_WAVELENGTH_M",
    "draw_drift_errors",
    "make_scenario",
    "make_world",
    "simulate_records",
]

KINDS = ("pool", "harbour", "random", "drift", "drawn")

#: Seeds from here on are held back: never used while tuning anything; results count on them.
HELD_BACK_SEED_MIN = 10_000

#: Drawn worlds: 1-sigma of the AHRS's constant heading bias, drawn per seed (deg); the
#: estimators are told this specification, never the realisation.
AHRS_BIAS_SIGMA_DEG = 2.0

#: The marina's Miniking: 500 bins of 0.1 m (50 m), 1.8 deg step, 3 deg beam, clockwise angles.
MARINA_HEAD = SonarHead(
    n_bins=500,
    bin_size_m=0.1,
    step_rad=math.radians(1.8),
    beam_width_rad=math.radians(3.0),
    angle_sense=-1,
)

#: The seed paper's pool test: 6 m range in 500 bins of 0.012 m, 0.45 deg step.
POOL_HEAD = replace(MARINA_HEAD, bin_size_m=0.012, step_rad=math.radians(0.45))

#: Marina-like mountings, chosen non-trivial so that every mounting code path is exercised.
SONAR_MOUNTING = Mounting(x_m=0.3, y_m=0.0, yaw_rad=math.pi, source="simulator truth")
DVL_MOUNTING = Mounting(yaw_rad=math.radians(-90.0), source="simulator truth")
AHRS_MOUNTING = Mounting(yaw_rad=0.0, source="simulator truth (the heading bias is in the noise)")

_DEFAULT_DURATION_S = {
    "pool": 165.0,
    "harbour": 600.0,
    "random": 600.0,
    "drift": 1800.0,
    "drawn": 1800.0,
}

#: Drift world: magnitude range of the DVL scale factor, drawn per seed with a random sign.
DRIFT_DVL_SCALE_RANGE = (0.01, 0.02)
#: ... and the 1-sigma the estimators are told (the specification's "1-2 %").
DRIFT_DVL_SCALE_SIGMA = 0.02
#: Drift world: each component of the DVL bias is uniform in +- this (m/s), per seed.
DRIFT_DVL_BIAS_MAX_MPS = 0.005
#: Drift world: intensity of the AHRS heading's random walk (deg/sqrt(s)): a standard deviation
#: of 6.4 deg after 1,800 s, a magnetic heading among steel walls and hulls.
DRIFT_HEADING_WALK_DEG_PER_SQRT_S = 0.15
#: Drift world: the echo peaks this far behind the wall face (m).
DRIFT_ECHO_RANGE_OFFSET_M = 0.25

# Drawn worlds' calibration errors, none of them told to the estimators: sized as the marina's
# own disagreements (docs/design-decisions.md, "The drawn worlds' calibration errors"), so that
# defaults chosen on drawn worlds transfer to it.

#: Drawn worlds: the sonar's range-scale error ``|s - 1|``, uniform in this range with a random
#: sign.
DRAWN_RANGE_SCALE_ERROR = (0.01, 0.04)
#: Drawn worlds: the true sonar mounting is ``sonarslam.toml``'s plus offsets uniform in
#: +- these (x and y m, yaw deg), unknown to the estimators.
DRAWN_MOUNT_OFFSET_MAX = (0.2, 0.2, 0.5)
#: Drawn worlds: RMS of the place-dependent AHRS heading disturbance (deg) and its wavelength
#: (m), on top of the walk.
DRAWN_HEADING_FIELD_DEG = 2.0
DRAWN_HEADING_FIELD_WAVELENGTH_M = 80.0


@dataclass(frozen=True)
class Scenario:
    """Everything that defines a simulated run.

    Attributes
    ----------
    kind : str
        ``"pool"`` (stationary sonar in the seed paper's pool), ``"harbour"`` (survey of a
        marina-like harbour), ``"random"`` (free path in a random rectilinear harbour) or
        ``"drift"`` (long survey of :func:`~sonarslam.datasets.simulator.world.drift_world`) or ``"drawn"``
        (long survey of a world drawn from the seed).
    seed : int
        Seed of every random draw (with the kind, see the module docstring).
    duration_s : float
        Length of the run (s).
    t0_s : float
        Start time (Unix s).
    head : SonarHead
    beam_rate_hz : float
        Sonar beams per second.
    sector_rad : float or None
        None for continuous 360 deg scanning, else the width of a back-and-forth sector.
    sonar_mounting, dvl_mounting, ahrs_mounting : Mounting
        True ``bTs`` of each sensor (written to ``sonarslam.toml``).
    noise : SensorNoise
    errors : DriftErrors or None
        Systematic sensor errors (DVL scale factor and bias, AHRS heading walk, echo range
        offset); None: none (the pool, harbour and random kinds).
    echo : EchoModel
    speed_mps : float
        Mean speed of the vehicle (m/s); unused for the pool.
    pool_sonar_yaw_rad : float
        Pool only: yaw of the sonar frame in the world (rad); the sonar sits at the origin.
    origin : GeodeticOrigin
        Geodetic point of the world origin.
    ahrs_bias_sigma_deg : float or None
        The AHRS constant bias's specification (1-sigma, deg) when it is drawn per seed; None:
        the estimators are told ``noise.ahrs_bias_deg`` itself (a fixed, known-size bias).
    sonar_mounting_told : Mounting or None
        The sonar mounting written to ``sonarslam.toml`` when it is not the true one (the
        estimators' prior); None: the true ``sonar_mounting``.
    path_rate_hz, dvl_rate_hz, ahrs_rate_hz, gps_rate_hz : float
        Sampling rates of the truth and the sensors (Hz).
    """

    kind: str = field(metadata={"choices": KINDS})
    seed: int
    duration_s: float = field(metadata={"range": Range(1.0, math.inf, low_open=True)})
    t0_s: float = T0_S
    head: SonarHead = field(default_factory=lambda: MARINA_HEAD)
    beam_rate_hz: float = 14.7
    sector_rad: float | None = None
    sonar_mounting: Mounting = SONAR_MOUNTING
    dvl_mounting: Mounting = DVL_MOUNTING
    ahrs_mounting: Mounting = AHRS_MOUNTING
    noise: SensorNoise = field(default_factory=SensorNoise)
    errors: DriftErrors | None = None
    echo: EchoModel = field(default_factory=EchoModel)
    speed_mps: float = 0.45
    pool_sonar_yaw_rad: float = math.radians(10.0)
    origin: GeodeticOrigin = MARINA_ORIGIN
    ahrs_bias_sigma_deg: float | None = None
    sonar_mounting_told: Mounting | None = None
    path_rate_hz: float = 50.0
    dvl_rate_hz: float = 1.5
    ahrs_rate_hz: float = 10.0
    gps_rate_hz: float = 1.0

    def __post_init__(self) -> None:
        check_fields(self)

    @property
    def prefix(self) -> str:
        """Common prefix of the log files, ``sim_<kind>_<seed>``."""
        return f"sim_{self.kind}_{self.seed}"

    def dataset_config(self) -> DatasetConfig:
        """The ``sonarslam.toml`` content: head, true mountings, and the noise the estimators
        should assume (the AHRS sigma includes the unmodelled constant bias, in quadrature)."""
        n = self.noise
        bias_deg = n.ahrs_bias_deg if self.ahrs_bias_sigma_deg is None else self.ahrs_bias_sigma_deg
        return DatasetConfig(
            sonar=self.head,
            sonar_mounting=(
                self.sonar_mounting
                if self.sonar_mounting_told is None
                else self.sonar_mounting_told
            ),
            dvl_mounting=self.dvl_mounting,
            ahrs_mounting=self.ahrs_mounting,
            noise=NoiseConfig(
                # a noise-free sensor (tests) still gets a usable sigma: the settings' floor
                dvl_sigma_mps=max(n.dvl_sigma_mps, 1e-3),
                ahrs_sigma_deg=max(math.hypot(n.ahrs_sigma_deg, bias_deg), 1e-3),
                gps_sigma_m=n.gps_sigma_m,
                dvl_max_gap_s=10.0,
                # a DVL that degrades: its usual scatter is its white noise (slam.model.motion)
                dvl_scatter_window_s=0.0 if n.dvl_degraded_from_s is None else 60.0,
                dvl_nominal_scatter_mps=n.dvl_sigma_mps,
                # the sensors' specifications: the rate of the AHRS's heading walk and the size
                # of the DVL's scale error (their realisations, the DVL's bias and the echo's
                # offset are not told)
                ahrs_bias_walk_deg_per_sqrt_s=(
                    0.0 if self.errors is None else self.errors.ahrs_heading_walk_deg_per_sqrt_s
                ),
                dvl_scale_sigma=0.0 if self.errors is None else DRIFT_DVL_SCALE_SIGMA,
            ),
        )


def draw_drift_errors(rng: np.random.Generator) -> DriftErrors:
    """The drift world's systematic errors of one seed: a DVL scale factor of 1-2 % with a random
    sign, a DVL bias uniform in +-5 mm/s per axis, the heading walk and the echo offset of this
    module's ``DRIFT_*`` constants."""
    lo, hi = DRIFT_DVL_SCALE_RANGE
    sign = 1.0 if rng.random() < 0.5 else -1.0
    scale = sign * float(rng.uniform(lo, hi))
    bias = rng.uniform(-DRIFT_DVL_BIAS_MAX_MPS, DRIFT_DVL_BIAS_MAX_MPS, 2)
    return DriftErrors(
        dvl_scale_factor=scale,
        dvl_bias_mps=(float(bias[0]), float(bias[1])),
        ahrs_heading_walk_deg_per_sqrt_s=DRIFT_HEADING_WALK_DEG_PER_SQRT_S,
        echo_range_offset_m=DRIFT_ECHO_RANGE_OFFSET_M,
    )


def make_scenario(kind: str, seed: int, duration_s: float | None = None) -> Scenario:
    """The default scenario of a kind.

    Parameters
    ----------
    kind : {"pool", "harbour", "random", "drift", "drawn"}
        Pool: stationary sonar at the world origin, 6 m range, 0.45 deg step, 0.5 m dead zone,
        165 s (three full turns at 14.7 beams/s). Harbour and random: the marina's head, 600 s.
        Drift: the marina's head, 1,800 s, the drift errors of the seed
        (:func:`draw_drift_errors`). Drawn: as drift, in the seed's own world, with the AHRS's
        constant bias drawn from N(0, :data:`AHRS_BIAS_SIGMA_DEG`).
    seed : int
    duration_s : float, optional
        Overrides the default length (s).

    Returns
    -------
    Scenario
    """
    if kind not in KINDS:
        raise ValueError(f"kind must be one of {KINDS}, got {kind!r}")
    duration = float(duration_s) if duration_s is not None else _DEFAULT_DURATION_S[kind]
    if kind == "pool":
        return Scenario(
            kind=kind,
            seed=seed,
            duration_s=duration,
            head=POOL_HEAD,
            echo=EchoModel(dead_zone_m=0.5, range_decay_per_m=0.02),
        )
    if kind == "drift":
        errors = draw_drift_errors(_seed_streams(seed, kind)["errors"])
        return Scenario(kind=kind, seed=seed, duration_s=duration, errors=errors)
    if kind == "drawn":
        streams = _seed_streams(seed, kind)
        bias_deg = float(streams["bias"].normal(0.0, AHRS_BIAS_SIGMA_DEG))
        cal = streams["calibration"]
        lo, hi = DRAWN_RANGE_SCALE_ERROR
        range_scale = 1.0 + (1.0 if cal.random() < 0.5 else -1.0) * float(cal.uniform(lo, hi))
        dx, dy, dyaw_deg = (float(cal.uniform(-m, m)) for m in DRAWN_MOUNT_OFFSET_MAX)
        told = SONAR_MOUNTING
        true_mount = Mounting(
            x_m=told.x_m + dx,
            y_m=told.y_m + dy,
            yaw_rad=told.yaw_rad + math.radians(dyaw_deg),
            source="simulator truth (sonarslam.toml has the mounting without its drawn offsets)",
        )
        errors = replace(
            draw_drift_errors(streams["errors"]),
            sonar_range_scale=range_scale,
            ahrs_heading_field_deg=DRAWN_HEADING_FIELD_DEG,
            ahrs_heading_field_wavelength_m=DRAWN_HEADING_FIELD_WAVELENGTH_M,
        )
        return Scenario(
            kind=kind,
            seed=seed,
            duration_s=duration,
            errors=errors,
            noise=SensorNoise(ahrs_bias_deg=bias_deg),
            ahrs_bias_sigma_deg=AHRS_BIAS_SIGMA_DEG,
            sonar_mounting=true_mount,
            sonar_mounting_told=replace(
                told,
                source="the simulator's nominal mounting (this world's drawn offsets are in"
                " truth.json only)",
            ),
        )
    return Scenario(kind=kind, seed=seed, duration_s=duration)


def _seed_streams(seed: int, kind: str) -> dict[str, np.random.Generator]:
    """One independent generator per component, from the seed and the kind (so that two kinds
    with the same seed do not share their noise). Names are only ever appended: spawning more
    children leaves the earlier ones, and so the older kinds' runs, as they were."""
    names = (
        "world",
        "path",
        "sonar",
        "dvl",
        "ahrs",
        "gps",
        "errors",
        "heading_walk",
        "bias",
        "calibration",
    )
    root = np.random.SeedSequence([seed, KINDS.index(kind)])
    return {n: np.random.default_rng(c) for n, c in zip(names, root.spawn(len(names)), strict=True)}


def _streams(scenario: Scenario) -> dict[str, np.random.Generator]:
    return _seed_streams(scenario.seed, scenario.kind)


def make_world(scenario: Scenario) -> World:
    """The world of a scenario (random worlds drawn from the scenario's own stream)."""
    if scenario.kind == "pool":
        return pool_world()
    if scenario.kind == "harbour":
        return harbour_world()
    if scenario.kind == "drift":
        return drift_world()
    if scenario.kind == "drawn":
        return drawn_world(_streams(scenario)["world"])
    return random_harbour_world(_streams(scenario)["world"])


@dataclass(frozen=True, eq=False)
class Simulation:
    """A simulated run in memory: the sensors' output and the truth.

    Attributes
    ----------
    scenario : Scenario
    world : World
    trajectory : TrueMotion
        True body motion (50 Hz); a ``PoseSource``.
    beams : list of SonarBeam
        Raw sonar beams.
    beam_axis_range_m, beam_axis_incidence_rad : ndarray, shape (B,)
        Geometric range and incidence of the first wall on each beam's axis (NaN if none).
    dvl : DvlSamples
    ahrs : AhrsSamples
    gps : GpsSamples
    """

    scenario: Scenario
    world: World
    trajectory: TrueMotion
    beams: list[SonarBeam] = field(repr=False)
    beam_axis_range_m: FloatArray = field(repr=False)
    beam_axis_incidence_rad: FloatArray = field(repr=False)
    dvl: DvlSamples = field(repr=False)
    ahrs: AhrsSamples = field(repr=False)
    gps: GpsSamples = field(repr=False)

    def records(self) -> list[Record]:
        """The sensor stream as the project's readers would give it, merged in time order.

        DVL velocities in the DVL frame (m/s), compass as yaw CCW from East; AHRS yaw CCW from
        East of the AHRS frame and its CCW rate; GPS fixes relative to the first fix (approximated
        by the difference of world East-North, within a few cm over a few hundred metres).
        At equal times the order is sonar, DVL, AHRS, GPS.
        """
        out: list[tuple[float, int, Record]] = []
        out += [(b.t, 0, b) for b in self.beams]
        d = self.dvl
        compass = wrap_angle(np.deg2rad(90.0 - d.compass_deg))
        for i in range(d.t_s.size):
            rec = DvlVelocity(
                t=float(d.t_s[i]),
                vx_mps=float(d.v_dvl_mps[i, 0]),
                vy_mps=float(d.v_dvl_mps[i, 1]),
                valid=bool(d.valid[i]),
                heading_rad=float(compass[i]),
            )
            out.append((rec.t, 1, rec))
        a = self.ahrs
        yaw = wrap_angle(np.deg2rad(90.0 - a.heading_deg))
        out += [
            (
                float(a.t_s[i]),
                2,
                Attitude(float(a.t_s[i]), float(yaw[i]), float(-a.rate_rad_per_s[i, 2])),
            )
            for i in range(a.t_s.size)
        ]
        g = self.gps
        local = g.enu_m - g.enu_m[0]
        out += [
            (float(g.t_s[i]), 3, GpsFix(float(g.t_s[i]), float(local[i, 0]), float(local[i, 1])))
            for i in range(g.t_s.size)
        ]
        out.sort(key=lambda x: (x[0], x[1]))
        return [r for _, _, r in out]


def _trajectory(scenario: Scenario, world: World, rng: np.random.Generator) -> TrueMotion:
    if scenario.kind == "pool":
        wTs = np.array([0.0, 0.0, scenario.pool_sonar_yaw_rad])
        wTb = compose(wTs, inverse(scenario.sonar_mounting.as_pose()))
        return stationary(wTb, scenario.duration_s, scenario.path_rate_hz, scenario.t0_s)
    if scenario.kind in ("harbour", "drift", "drawn"):
        return survey(
            world, scenario.duration_s, scenario.speed_mps, scenario.path_rate_hz, scenario.t0_s
        )
    return free_path(
        world,
        rng,
        scenario.duration_s,
        speed_mps=scenario.speed_mps,
        rate_hz=scenario.path_rate_hz,
        t0_s=scenario.t0_s,
    )


def simulate_records(scenario: Scenario) -> Simulation:
    """Simulate a scenario in memory.

    Parameters
    ----------
    scenario : Scenario

    Returns
    -------
    Simulation
    """
    rngs = _streams(scenario)
    world = make_world(scenario)
    trajectory = _trajectory(scenario, world, rngs["path"])
    errors = scenario.errors
    beams = simulate_msis(
        world,
        scenario.head,
        scenario.sonar_mounting,
        trajectory,
        rngs["sonar"],
        rate_hz=scenario.beam_rate_hz,
        sector_rad=scenario.sector_rad,
        echo=scenario.echo,
        range_offset_m=0.0 if errors is None else errors.echo_range_offset_m,
        range_scale=1.0 if errors is None else errors.sonar_range_scale,
    )
    t_beam = np.array([b.t for b in beams])
    a_beam = np.array([b.transducer_angle_rad for b in beams])
    r_axis, inc_axis = beam_axis_hits(
        world, scenario.head, scenario.sonar_mounting, trajectory.poses(t_beam), a_beam
    )
    n = scenario.noise
    return Simulation(
        scenario=scenario,
        world=world,
        trajectory=trajectory,
        beams=beams,
        beam_axis_range_m=r_axis,
        beam_axis_incidence_rad=inc_axis,
        dvl=simulate_dvl(
            trajectory, scenario.dvl_mounting, n, rngs["dvl"], scenario.dvl_rate_hz, errors=errors
        ),
        ahrs=simulate_ahrs(
            trajectory,
            scenario.ahrs_mounting,
            n,
            rngs["ahrs"],
            scenario.ahrs_rate_hz,
            errors=errors,
            walk_rng=rngs["heading_walk"],
        ),
        gps=simulate_gps(trajectory, scenario.origin, n, rngs["gps"], scenario.gps_rate_hz),
    )
