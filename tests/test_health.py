"""The health monitor (slam.eval.health): each check trips on the fault it is for and stays
quiet on consistent logs; on the simulator, a closed loop with an injected fault is flagged and
clean runs are not."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from scipy.stats import chi2

from sonarslam.slam.eval.health import (
    HealthConfig,
    HealthInputs,
    NisStream,
    StateValue,
    assess,
    median_lower_bound,
    median_upper_bound,
)
from sonarslam.slam.eval.loops import OdometryCheck
from sonarslam.slam.io.trajectory import Trajectory

T0 = 1.7e9
DURATION_S = 1200.0


def _trajectory(rng: np.random.Generator, offset_m: float = 0.0) -> Trajectory:
    """A straight run at 0.5 m/s with a position covariance growing to 1 m^2."""
    t = T0 + np.arange(0.0, DURATION_S, 1.0)
    poses = np.column_stack([0.5 * (t - T0) + offset_m, np.zeros_like(t), np.zeros_like(t)])
    covs = np.zeros((t.size, 3, 3))
    covs[:, 0, 0] = covs[:, 1, 1] = 0.01 + (t - T0) / DURATION_S
    covs[:, 2, 2] = 1e-4
    return Trajectory(t, poses, covs)


def _inputs(rng: np.random.Generator, **changes: object) -> HealthInputs:
    """Consistent logs: the estimate on dead reckoning, the AHRS on the heading with a 1 deg
    bias and 1 deg noise, chi2 NIS gated at 99 %, landmarks re-observed."""
    tr = _trajectory(rng)
    t_ahrs = T0 + np.arange(0.0, DURATION_S, 0.1)
    yaw = np.deg2rad(1.0 + rng.normal(0.0, 1.0, t_ahrs.size))
    t_line = np.sort(rng.uniform(T0, T0 + DURATION_S, 600))
    nis = chi2.rvs(2, size=2000, random_state=rng)
    nis = nis[nis <= chi2.ppf(0.99, 2)][: t_line.size]
    t_h = T0 + np.arange(0.0, DURATION_S, 1.0)
    base = HealthInputs(
        trajectory=tr,
        reference=_trajectory(rng),
        ahrs_t_s=t_ahrs,
        ahrs_yaw_rad=yaw,
        ahrs_bias_sigma_rad=np.deg2rad(2.0),
        ahrs_bias_walk_rad_per_sqrt_s=0.0,
        nis=[
            NisStream("line", t_line, nis, 2, 0.99),
            NisStream("heading", t_h, chi2.rvs(1, size=t_h.size, random_state=rng), 1),
        ],
        landmark_created_s=T0 + np.array([10.0, 20.0, 30.0, 400.0, 800.0]),
        reobserved_s=t_line,
        states=[StateValue("AHRS bias", 1.2, 2.0, "deg")],
    )
    return replace(base, **changes)  # type: ignore[arg-type]


@pytest.mark.parametrize("seed", range(10))
def test_consistent_logs_raise_nothing(seed: int) -> None:
    report = assess(_inputs(np.random.default_rng(seed)))
    assert report.ok, [i.message(report.t_ref_s) for i in report.issues]
    assert not report.findings, [i.message(report.t_ref_s) for i in report.findings]
    m = report.metrics()
    assert m["health_ok"] is True and m["health_issues"] == 0
    assert m["health_underconfident"] == [] and m["health_first_finding"] is None
    assert m["health_nis_line_windows"] == 15 and m["health_departure_windows"] == 10
    assert "no inconsistency found" in report.line()


def _travel(angle_deg: float, rng: np.random.Generator, n: int = 600) -> np.ndarray:
    """Body-frame velocities (n, 2) of 0.5 m/s toward ``angle_deg`` off the bow, with 0.1 m/s
    of noise."""
    a = np.deg2rad(angle_deg)
    return np.array([0.5 * np.cos(a), 0.5 * np.sin(a)]) + rng.normal(0.0, 0.1, (n, 2))


@pytest.mark.parametrize(
    ("angle_deg", "flagged"), [(0.0, False), (-26.0, False), (180.0, True), (90.0, True)]
)
def test_travel_off_the_bow_trips_the_travel_check(angle_deg: float, flagged: bool) -> None:
    """A DVL given the wrong way round moves dead reckoning stern- or side-first; the run is
    consistent with itself otherwise (the sonar's yaw calibrated on it took the same turn), so
    only this check says so. The marina travels 26 deg off its bow on the whole (crabbing)."""
    rng = np.random.default_rng(3)
    report = assess(_inputs(rng, travel_body_mps=_travel(angle_deg, rng)))
    assert report.judged["travel"] == 1
    assert ("travel" in report.checks_flagged()) is flagged
    if flagged:
        cause = [i.cause for i in report.issues if i.check == "travel"][0]
        assert f"{angle_deg:+.0f} deg off its bow" in cause and "[mounting.dvl]" in cause
        assert not report.line().startswith("health: no inconsistency found")
    else:
        assert report.ok


def test_a_vehicle_that_travels_every_way_is_not_judged_by_the_travel_check() -> None:
    """Hovering or a pool's back-and-forth: the travel has no direction to judge."""
    rng = np.random.default_rng(4)
    back_and_forth = np.concatenate([_travel(0.0, rng, 300), _travel(180.0, rng, 300)])
    report = assess(_inputs(rng, travel_body_mps=back_and_forth))
    assert report.ok and "travel" not in report.judged


@pytest.mark.parametrize(
    ("heading_deg", "accepted", "flagged"),
    [(-174.0, 8, True), (60.0, 3, True), (30.0, 8, False), (-174.0, 2, False)],
)
def test_the_sonar_turned_from_dead_reckoning_trips_the_odometry_check(
    heading_deg: float, accepted: int, flagged: bool
) -> None:
    """Beyond 45 deg over at least 3 registrations: a sensor mounted the wrong way round."""
    check = OdometryCheck(12, accepted, heading_deg, 1.0, 5.0, 0.01)
    report = assess(_inputs(np.random.default_rng(5), odometry=check))
    assert report.judged["odometry"] == 1
    assert ("odometry" in report.checks_flagged()) is flagged
    assert report.ok is not flagged
    if flagged:
        assert f"{heading_deg:+.0f} deg away" in report.issues[0].cause


def test_innovations_three_times_their_variance_trip_the_nis_check() -> None:
    rng = np.random.default_rng(1)
    inputs = _inputs(rng)
    line = inputs.nis[0]
    late = line.t_s > T0 + 600.0
    inflated = np.where(late, 3.0 * line.nis, line.nis)  # S three times too small after 600 s
    inflated = np.minimum(inflated, chi2.ppf(0.99, 2))  # the gate still truncates them
    report = assess(replace(inputs, nis=[replace(line, nis=inflated), inputs.nis[1]]))
    flagged = [i for i in report.issues if i.check == "nis_line"]
    assert flagged and {i.check for i in report.issues} == {"nis_line"}
    assert flagged[0].t0_s >= T0 + 600.0 - 1e-6  # the span where it went wrong
    assert "line innovations too large" in flagged[0].cause


def test_innovations_a_twentieth_of_their_variance_are_a_finding_not_an_issue() -> None:
    """The marina EKF's heading (docs/research/consistency.md): after 600 s the heading NIS is a twentieth
    of chi2(1) (a prediction that already holds the AHRS heading it is compared with). The
    monitor reports it as under-confident, on that span only, and the run stays healthy: no
    issue, no warning."""
    import warnings

    rng = np.random.default_rng(11)
    inputs = _inputs(rng)
    heading = inputs.nis[1]
    late = heading.t_s > T0 + 600.0
    shrunk = replace(heading, nis=np.where(late, 0.05 * heading.nis, heading.nis))
    report = assess(replace(inputs, nis=[inputs.nis[0], shrunk]))
    assert report.ok and not report.issues
    assert {f.check for f in report.findings} == {"nis_heading"}
    # on that span only, most of it (a group's median 0.023 against the limit 0.15: the
    # bound of the median at 1 % over 30 groups of 40 misses a few groups)
    assert all(f.t0_s >= T0 + 600.0 - 1e-6 for f in report.findings)
    covered = sum(f.t1_s - f.t0_s for f in report.findings)
    assert covered >= 0.6 * 600.0, covered
    assert all("smaller than predicted" in f.cause for f in report.findings)
    m = report.metrics()
    assert m["health_ok"] is True and m["health_flagged"] == []
    assert m["health_underconfident"] == ["nis_heading"]
    assert m["health_nis_heading_underconfident"] == len(report.findings)
    assert m["health_nis_line_underconfident"] == 0
    assert "under-confident, not an error: nis_heading" in report.line()
    assert report.line().startswith("health: no inconsistency found")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        report.warn()  # findings do not warn


def test_an_overconfident_and_an_underconfident_stream_are_told_apart() -> None:
    """Line NIS three times too large (an issue) beside heading NIS a fifth of chi2(1) (a
    finding): each in its own list."""
    rng = np.random.default_rng(12)
    inputs = _inputs(rng)
    line, heading = inputs.nis
    big = np.minimum(3.0 * line.nis, chi2.ppf(0.99, 2))
    report = assess(
        replace(inputs, nis=[replace(line, nis=big), replace(heading, nis=0.2 * heading.nis)])
    )
    assert report.checks_flagged() == ["nis_line"]
    assert report.checks_underconfident() == ["nis_heading"]
    assert not report.ok
    assert "under-confident, not an error: nis_heading" in report.line()


def test_a_covariance_far_too_large_is_an_underconfident_nees_finding() -> None:
    """From 600 s on the pose covariance is a thousand times the error's: the NEES windows
    there are reported under-confident, none flagged. The lower limit assumes nothing about the
    samples' correlation (a window's median may be one chi2(3) draw), so it is far down: over
    10 windows at the default false alarm, 0.0153 against the median 2.37; a hundredfold too
    cautious (median 0.024) is not below it."""
    rng = np.random.default_rng(13)
    inputs = _inputs(rng)
    tr = inputs.trajectory
    truth = _truth_of(tr, rng)
    assert tr.covs is not None
    covs = tr.covs.copy()
    covs[tr.t_s >= T0 + 600.0] *= 1000.0  # a thousand times too cautious from 600 s on
    report = assess(replace(inputs, trajectory=Trajectory(tr.t_s, tr.poses_wTb, covs), truth=truth))
    assert report.ok, report.line()
    assert {f.check for f in report.findings} == {"nees"}
    assert all(f.t0_s >= T0 + 600.0 - 1e-6 for f in report.findings)
    covered = sum(f.t1_s - f.t0_s for f in report.findings)
    assert covered >= 0.6 * 600.0, covered
    assert report.metrics()["health_nees_underconfident"] == len(report.findings)


def test_a_departure_from_dead_reckoning_beyond_both_covariances_is_flagged() -> None:
    rng = np.random.default_rng(2)
    inputs = _inputs(rng)
    tr = inputs.trajectory
    poses = tr.poses_wTb.copy()
    poses[:, 1] += np.clip((tr.t_s - T0 - 900.0) * 0.05, 0.0, None)  # 15 m off by the end
    report = assess(replace(inputs, trajectory=Trajectory(tr.t_s, poses, tr.covs)))
    (issue,) = [i for i in report.issues if i.check == "departure"]
    assert T0 + 900.0 <= issue.t0_s <= T0 + 1080.0
    assert "from dead reckoning" in issue.cause


def test_a_bias_beyond_ten_prior_sigmas_and_a_spinning_heading_are_flagged() -> None:
    rng = np.random.default_rng(3)
    inputs = _inputs(rng)
    report = assess(replace(inputs, states=[StateValue("AHRS bias", 1835.6, 8.9, "deg")]))
    assert [i.check for i in report.issues] == ["state"]
    assert "1836 deg" in report.issues[0].cause
    # the AHRS 0.66 deg/s away from an estimate that follows a biased gyro: unwrapped
    tr = inputs.trajectory
    poses = tr.poses_wTb.copy()
    poses[:, 2] = np.deg2rad(0.66) * (tr.t_s - T0)
    spun = replace(inputs, trajectory=Trajectory(tr.t_s, poses, tr.covs))
    issues = [i for i in assess(spun).issues if i.check == "heading_bias"]
    assert issues and issues[0].t0_s <= T0 + 240.0
    assert issues[-1].t1_s == pytest.approx(tr.t_s[-1])


def test_a_covariance_that_is_not_positive_definite_is_flagged() -> None:
    rng = np.random.default_rng(4)
    inputs = _inputs(rng)
    tr = inputs.trajectory
    assert tr.covs is not None
    covs = tr.covs.copy()
    covs[500:, 2, 2] = -1e-6
    report = assess(replace(inputs, trajectory=Trajectory(tr.t_s, tr.poses_wTb, covs)))
    (issue,) = report.issues
    assert issue.check == "state" and "not positive definite" in issue.cause
    assert issue.t0_s == pytest.approx(tr.t_s[500])


def test_landmarks_created_instead_of_reobserved_are_flagged() -> None:
    rng = np.random.default_rng(5)
    inputs = _inputs(rng)
    created = np.concatenate([inputs.landmark_created_s, T0 + np.linspace(1000.0, 1150.0, 30)])
    again = inputs.reobserved_s[inputs.reobserved_s < T0 + 960.0]
    report = assess(replace(inputs, landmark_created_s=created, reobserved_s=again))
    assert {i.check for i in report.issues} == {"landmarks"}
    assert report.issues[0].t0_s >= T0 + 960.0
    # its causes include the IMU's frame convention, which no reader check refuses when the
    # orientation and the gyro are both NED (issue 32's review)
    cause = report.issues[0].cause
    assert "IMU's frame convention" in cause and "[sonar] angle_sense" in cause


def _truth_of(tr: Trajectory, rng: np.random.Generator, rho: float = 0.99) -> Trajectory:
    """A truth that the estimate ``tr`` is off by a slowly drifting error (AR(1) with ``rho`` per
    sample) whose marginal is N(0, P_k) at each sample: a consistent estimate."""
    assert tr.covs is not None
    w = rng.normal(size=(tr.t_s.size, 3))
    z = np.empty_like(w)
    z[0] = w[0]
    for k in range(1, z.shape[0]):
        z[k] = rho * z[k - 1] + np.sqrt(1.0 - rho**2) * w[k]
    e = np.einsum("kij,kj->ki", np.linalg.cholesky(tr.covs), z)
    return Trajectory(tr.t_s, tr.poses_wTb - e)


@pytest.mark.parametrize("seed", range(5))
def test_a_consistent_nees_against_the_truth_raises_nothing(seed: int) -> None:
    rng = np.random.default_rng(100 + seed)
    inputs = _inputs(rng)
    report = assess(replace(inputs, truth=_truth_of(inputs.trajectory, rng)))
    assert report.ok, report.line()
    assert report.metrics()["health_nees_windows"] == 10


def test_a_covariance_ten_times_too_small_trips_the_nees_check() -> None:
    rng = np.random.default_rng(8)
    inputs = _inputs(rng)
    tr = inputs.trajectory
    truth = _truth_of(tr, rng)
    assert tr.covs is not None
    covs = tr.covs.copy()
    covs[tr.t_s >= T0 + 600.0] /= 10.0  # overconfident from 600 s on
    report = assess(replace(inputs, trajectory=Trajectory(tr.t_s, tr.poses_wTb, covs), truth=truth))
    assert {i.check for i in report.issues} == {"nees"}, report.line()
    # only the windows after 600 s, most of them (a 10x NEES median is 23.7, the limit 17.7)
    assert all(i.t0_s >= T0 + 600.0 - 1e-6 for i in report.issues)
    covered = sum(i.t1_s - i.t0_s for i in report.issues)
    assert covered >= 0.6 * 600.0, covered
    assert all("median NEES" in i.cause and "against the truth" in i.cause for i in report.issues)
    # a span of several windows gives its worst window's median, and says so
    assert all("in the worst 120 s window" in i.cause for i in report.issues)
    m = report.metrics()
    assert m["health_nees_flagged"] == len(report.issues) and m["health_flagged"] == ["nees"]


def test_the_nees_check_holds_its_level_on_fully_correlated_windows() -> None:
    """The worst case for a window: one error held over all of its samples (the median is one
    chi2(3) draw). The check still raises at most ``false_alarm`` of consistent runs (here about
    half of it: Markov's factor 2 is the price of assuming nothing about the correlation)."""
    rng = np.random.default_rng(9)
    cfg = HealthConfig(false_alarm=0.2)
    tr = _trajectory(rng)
    assert tr.covs is not None
    chol = np.linalg.cholesky(tr.covs)
    window = ((tr.t_s - T0) // cfg.window_s).astype(int)
    # the NEES check alone: no NIS, no dead reckoning, no AHRS
    base = HealthInputs(tr, None, np.zeros(0), np.zeros(0), 0.0, 0.0)
    trials, raised = 400, 0
    for _ in range(trials):
        z = rng.normal(size=(window.max() + 1, 3))[window]
        truth = Trajectory(tr.t_s, tr.poses_wTb - np.einsum("kij,kj->ki", chol, z))
        report = assess(replace(base, trajectory=tr, truth=truth), cfg)
        raised += "nees" in report.checks_flagged()
    rate = raised / trials
    assert 0.03 <= rate <= cfg.false_alarm + 3.0 * np.sqrt(0.2 * 0.8 / trials), rate


def test_the_median_bound_holds_its_level() -> None:
    """Distribution-free: the lower bound exceeds the true median in at most alpha of the
    windows (chi2(2) samples, 2,000 windows of 30)."""
    rng = np.random.default_rng(6)
    alpha = 0.05
    bounds = np.array(
        [median_lower_bound(chi2.rvs(2, size=30, random_state=rng), alpha) for _ in range(2000)]
    )
    exceed = np.mean(bounds > chi2.median(2))
    assert exceed <= alpha + 0.015, exceed
    assert median_lower_bound(np.ones(2), 1e-3) == -np.inf  # too few to bound
    uppers = np.array(
        [median_upper_bound(chi2.rvs(2, size=30, random_state=rng), alpha) for _ in range(2000)]
    )
    below = np.mean(uppers < chi2.median(2))
    assert below <= alpha + 0.015, below
    assert median_upper_bound(np.ones(2), 1e-3) == np.inf


def test_the_warnings_name_the_span_and_the_cause() -> None:
    from sonarslam.datasets.errors import DataWarning

    rng = np.random.default_rng(7)
    report = assess(_inputs(rng, states=[StateValue("AHRS bias", 50.0, 2.0, "deg")]))
    with pytest.warns(DataWarning, match=r"health: state at 0-1199 s into the run: the final"):
        report.warn()
    assert report.metrics()["health_flagged"] == ["state"]


def test_the_config_is_range_checked() -> None:
    with pytest.raises(ValueError, match="false_alarm"):
        HealthConfig(false_alarm=0.9)


# -- end to end on the simulator -----------------------------------------------------------


@pytest.fixture(scope="module")
def gyro_harbour(tmp_path_factory):
    """300 s of a held-back harbour whose gyro reads the true rate plus the marina MTi's
    0.01 rad/s; and the same world with a clean gyro."""
    import warnings

    from sonarslam.datasets.simulator import make_scenario, simulate_records
    from sonarslam.datasets.simulator.writer import write_dataset
    from sonarslam.datasets.source import open_dataset

    scenario = make_scenario("harbour", 10001, 300.0)
    out = {}
    for name, bias in (("clean", 0.0), ("biased", 0.01)):
        noise = replace(scenario.noise, ahrs_gyro_bias_rad_per_s=bias)
        sim = simulate_records(replace(scenario, noise=noise))
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            out[name] = open_dataset(write_dataset(sim, tmp_path_factory.mktemp(name)))
    return out


def _quiet_run(ds, backend, settings=None):
    import warnings

    from sonarslam.slam.run.run import run_backend

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return run_backend(ds, backend, settings).metrics


@pytest.mark.parametrize("backend", ["ekf", "isam2"])
def test_clean_simulated_runs_are_healthy(gyro_harbour, backend):
    m = _quiet_run(gyro_harbour["clean"], backend)
    assert m["health_ok"], m["health_first_issue"]
    assert m["health_nis_line_windows"] >= 1 and m["health_departure_windows"] >= 2
    assert m["health_nees_windows"] >= 2 and m["health_nees_flagged"] == 0


@pytest.mark.parametrize("backend", ["ekf", "isam2"])
def test_an_overconfident_ahrs_bias_prior_is_flagged_by_the_nees_alone(gyro_harbour, backend):
    """The simulated AHRS reads 2 deg off; told its bias is 0 +- 0.05 deg, either back end
    follows it with a heading variance 1,600 times too small. Nothing GPS-free sees it (the
    estimate agrees with the AHRS and with dead reckoning); the NEES against the truth does,
    and the run warns."""
    import warnings

    from sonarslam.datasets.errors import DataWarning
    from sonarslam.slam.run.run import run_backend

    ds = gyro_harbour["clean"]
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        m = run_backend(ds, backend, {f"{backend}.noise.ahrs_bias_sigma_deg": 0.05}).metrics
    assert m["health_flagged"] == ["nees"], m["health_first_issue"]
    assert m["health_ok"] is False and m["health_nees_flagged"] >= 1
    assert "median NEES" in m["health_first_issue"] and "(nees)" in m["health_line"]
    said = [str(w.message) for w in caught if issubclass(w.category, DataWarning)]
    assert any(w.startswith("health: nees at 0-") for w in said), said


def test_an_unmodelled_gyro_bias_with_a_walking_ahrs_bias_trips_the_monitor(gyro_harbour):
    """The marina's failure on the simulator: the EKF's gyro-bias state held at 0 and the AHRS
    bias allowed to walk. With the state (the default) the same data is healthy."""
    ds = gyro_harbour["biased"]
    noise = replace(ds.config.noise, ahrs_bias_walk_deg_per_sqrt_s=0.15)
    walking = replace(ds, config=replace(ds.config, noise=noise))
    bad = _quiet_run(walking, "ekf", {"ekf.gyro_bias_sigma_deg_per_s": 1e-6})
    assert not bad["health_ok"]
    assert {"heading_bias", "nis_heading"} & set(bad["health_flagged"]), bad["health_flagged"]
    good = _quiet_run(walking, "ekf")
    assert good["health_ok"], good["health_first_issue"]
    assert good["state_gyro_bias_deg_per_s"] == pytest.approx(np.rad2deg(0.01), rel=0.1)


def test_isam2_without_a_gyro_bias_state_is_flagged_on_a_biased_gyro(gyro_harbour):
    """The runner refuses isam2 with the gyro and a walking AHRS bias; run through the closed
    loop anyway, the monitor flags it."""
    from sonarslam.slam.backends.registry import backend_spec
    from sonarslam.slam.run.closed_loop import run_closed_loop
    from sonarslam.slam.run.health import monitor_run
    from sonarslam.slam.run.presets import run_config

    ds = gyro_harbour["biased"]
    noise = replace(ds.config.noise, ahrs_bias_walk_deg_per_sqrt_s=0.15)
    ds = replace(ds, config=replace(ds.config, noise=noise))
    config = run_config(ds.beams, "isam2", None, ds.config.noise)
    mount = ds.config.sonar_mounting
    result = run_closed_loop(
        ds,
        lambda t0, p0, c0: backend_spec("isam2").make(t0, p0, c0, mount, config.backend),
        config.extractor,
        progress=False,
    )
    report = monitor_run(ds, result)
    assert not report.ok and "heading_bias" in report.checks_flagged(), report.line()


def test_strict_exits_1_on_an_unhealthy_run_and_still_writes_it(gyro_harbour, tmp_path, capsys):
    from sonarslam.slam.cli.main import main

    walk = tmp_path / "walk.toml"
    walk.write_text("[noise]\nahrs_bias_walk_deg_per_sqrt_s = 0.15\n")
    out = tmp_path / "o"
    args = ["run", str(gyro_harbour["biased"].root), "--backend", "ekf", "--config", str(walk)]
    args += ["--set", "ekf.gyro_bias_sigma_deg_per_s=1e-6", "--out", str(out), "--quiet"]
    assert main([*args, "--strict"]) == 1
    cap = capsys.readouterr()
    assert "warning: health: " in cap.err and "error: --strict:" in cap.err.splitlines()[-1]
    assert "health: " in cap.out and (out / "metrics.json").is_file()


@pytest.mark.parametrize("backend", ["ekf", "isam2"])
def test_line_covariances_told_ten_times_too_large_are_underconfident(gyro_harbour, backend):
    """Either back end told that its lines are ten times noisier than they are
    (``line_cov_scale = 10``): the line NIS falls far below chi2(2), which the monitor reports
    as under-confident, and the run stays healthy (no issue for it, no warning)."""
    import warnings

    from sonarslam.datasets.errors import DataWarning
    from sonarslam.slam.run.run import run_backend

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        m = run_backend(gyro_harbour["clean"], backend, {f"{backend}.line_cov_scale": 10.0}).metrics
    assert "nis_line" in m["health_underconfident"], m["health_line"]
    assert m["health_nis_line_underconfident"] >= 1 and m["health_nis_line_flagged"] == 0
    assert "line innovations smaller than predicted" in m["health_first_finding"]
    assert "under-confident, not an error" in m["health_line"]
    said = [str(w.message) for w in caught if issubclass(w.category, DataWarning)]
    assert not any("smaller than predicted" in w for w in said), said


def test_a_run_of_thousands_of_beams_without_lines_is_flagged_with_its_causes() -> None:
    """Beam angles in gradians read as radians gave 0 lines from 5,871 beams and "no
    inconsistency found" (every check judges lines or innovations, and there were none): the
    ``lines`` check flags it, naming the likely causes; the simulated harbour's yield (61 lines
    from 5,862 beams) and a run too short to judge pass."""
    rng = np.random.default_rng(3)
    silent = assess(_inputs(rng, n_beams=5871, n_lines=0))
    assert not silent.ok and silent.checks_flagged() == ["lines"]
    line = silent.line()
    assert "\n" not in line
    assert "0 lines from 5871 beams" in line and "dead reckoning" in line
    for cause in ("not in radians", "intensity_threshold", "max_range_m"):
        assert cause in line
    assert assess(_inputs(rng, n_beams=5871, n_lines=5)).checks_flagged() == ["lines"]
    good = assess(_inputs(rng, n_beams=5862, n_lines=61))
    assert good.ok and good.metrics()["health_lines_windows"] == 1
    short = assess(_inputs(rng, n_beams=1500, n_lines=0))
    assert short.ok and "health_lines_windows" not in short.metrics()


def test_an_issue_ends_where_the_run_ends_and_the_line_counts_each_check() -> None:
    """A 1,100 s run flagged in its last 120 s window and in another: the issue ends at the
    run's end, not at the window's (it read '960-1080 s' past a run's end), and the line counts
    two issues of one check as such (it read '2 inconsistencies (landmarks)')."""
    rng = np.random.default_rng(5)
    inputs = _inputs(rng)
    tr = inputs.trajectory
    keep = tr.t_s <= T0 + 1100.0
    assert tr.covs is not None
    short = Trajectory(tr.t_s[keep], tr.poses_wTb[keep], tr.covs[keep])
    created = np.concatenate(
        [
            inputs.landmark_created_s,
            T0 + np.linspace(250.0, 350.0, 30),
            T0 + np.linspace(1082.0, 1098.0, 30),
        ]
    )
    seen = inputs.reobserved_s
    again = seen[(seen < T0 + 960.0) & ~((seen >= T0 + 240.0) & (seen < T0 + 360.0))]
    report = assess(
        replace(inputs, trajectory=short, landmark_created_s=created, reobserved_s=again)
    )
    assert [i.check for i in report.issues] == ["landmarks", "landmarks"], report.line()
    assert report.issues[-1].t1_s == pytest.approx(short.t_s[-1], abs=1e-6)
    assert "2 inconsistencies in the online loop (landmarks x2)" in report.line()


def test_the_first_window_builds_the_map_and_is_not_judged_by_the_landmarks_check() -> None:
    """A correct run's first 120 s create most of its landmarks (the map starts empty): a
    review's drawn world 23 was flagged there ('9 landmarks created against 7
    re-observations') with the true calibration, and --strict exited 1. The same share in a
    later window is still flagged."""
    rng = np.random.default_rng(6)
    inputs = _inputs(rng)
    seen = inputs.reobserved_s
    first = np.concatenate([T0 + np.linspace(5.0, 100.0, 9), inputs.landmark_created_s[3:]])
    again = np.concatenate([T0 + np.linspace(10.0, 110.0, 7), seen[seen >= T0 + 120.0]])
    assert assess(replace(inputs, landmark_created_s=first, reobserved_s=again)).ok
    later = np.concatenate([inputs.landmark_created_s, T0 + np.linspace(485.0, 580.0, 9)])
    again = seen[(seen < T0 + 480.0) | (seen >= T0 + 600.0)]
    again = np.concatenate([again, T0 + np.linspace(490.0, 590.0, 7)])
    report = assess(replace(inputs, landmark_created_s=later, reobserved_s=again))
    assert [i.check for i in report.issues] == ["landmarks"], report.line()
