"""The line extractor end to end on a small synthetic MSIS written here (not datasets/simulator).

The generator casts the rays of each beam against wall segments in the world: a wall returns an
echo when the ray's incidence on it is at most beta. Return models: ``"axis"`` (the echo where the
beam axis meets the wall), ``"uniform"`` (at a random bearing within the beam width) and
``"first_return"`` (the nearest echo over the beam width).
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import numpy.typing as npt
import pytest

from sonarslam.features.config import ExtractorConfig
from sonarslam.features.extractor import LineExtractor
from sonarslam.features.geometry import compose, line_world_to_frame, wrap_angle
from sonarslam.features.line import LineFeature
from sonarslam.features.pose_source import PoseSource, PoseSpanWarning
from sonarslam.settings import SettingError
from sonarslam.slam.io.trajectory import Trajectory
from sonarslam.slam.run.presets import EXTRACTOR_PRESETS
from sonarslam.sonar.beam import Mounting, SonarBeam, SonarHead

#: The marina keyframes' preset with the least-squares covariance (180 deg, 10 votes)
MARINA_FIT = EXTRACTOR_PRESETS["marina-fit"]

BETA = np.deg2rad(25.0)


# -- pose sources ---------------------------------------------------------------------------


@dataclass
class ConstantVelocityPoses:
    """Truth: a vehicle at constant velocity (world) and constant yaw rate from ``t0_s``."""

    start: tuple[float, float, float] = (0.0, 0.0, 0.0)
    velocity_mps: tuple[float, float] = (0.0, 0.0)
    yaw_rate_rad_per_s: float = 0.0
    t0_s: float = 0.0

    def poses(self, t_s: npt.ArrayLike) -> np.ndarray:
        dt = np.atleast_1d(np.asarray(t_s, dtype=np.float64)) - self.t0_s
        x = self.start[0] + self.velocity_mps[0] * dt
        y = self.start[1] + self.velocity_mps[1] * dt
        yaw = wrap_angle(self.start[2] + self.yaw_rate_rad_per_s * dt)
        return np.stack([x, y, yaw], axis=-1)

    def covariance(self, t_s: float) -> np.ndarray | None:
        return None


@dataclass
class FrozenPoses:
    """A pose source that ignores the motion: the same pose at every time."""

    pose: tuple[float, float, float]

    def poses(self, t_s: npt.ArrayLike) -> np.ndarray:
        n = np.atleast_1d(np.asarray(t_s)).size
        return np.tile(np.asarray(self.pose, dtype=np.float64), (n, 1))

    def covariance(self, t_s: float) -> np.ndarray | None:
        return None


# -- the synthetic sonar ----------------------------------------------------------------------


def rectangle_walls(
    center: tuple[float, float], size_m: tuple[float, float], yaw_rad: float
) -> np.ndarray:
    """The four walls of a rectangle, rows ``(x0, y0, x1, y1)``, shape (4, 4)."""
    hx, hy = size_m[0] / 2, size_m[1] / 2
    corners_local = np.array([[hx, hy], [-hx, hy], [-hx, -hy], [hx, -hy]])
    c, s = np.cos(yaw_rad), np.sin(yaw_rad)
    corners = corners_local @ np.array([[c, s], [-s, c]]) + np.asarray(center)
    return np.hstack([corners, np.roll(corners, -1, axis=0)])


def wall_lines_world(walls: np.ndarray) -> np.ndarray:
    """``(rho, theta)`` world lines of wall segments, shape (W, 2)."""
    d = walls[:, 2:] - walls[:, :2]
    theta = np.arctan2(d[:, 0], -d[:, 1])  # a normal of the segment
    rho = walls[:, 0] * np.cos(theta) + walls[:, 1] * np.sin(theta)
    flip = rho < 0
    return np.stack([np.abs(rho), wrap_angle(np.where(flip, theta + np.pi, theta))], axis=-1)


def _ray_hits(origin: np.ndarray, angles: np.ndarray, walls: np.ndarray) -> tuple:
    """Nearest wall along each ray: range (inf if none) and incidence (rad)."""
    u = np.stack([np.cos(angles), np.sin(angles)], axis=-1)[:, None, :]  # (R, 1, 2)
    p0, e = walls[None, :, :2], (walls[:, 2:] - walls[:, :2])[None]
    w = p0 - origin
    den = u[..., 0] * e[..., 1] - u[..., 1] * e[..., 0]
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (w[..., 0] * e[..., 1] - w[..., 1] * e[..., 0]) / den
        s = (w[..., 0] * u[..., 1] - w[..., 1] * u[..., 0]) / den
    t = np.where((np.abs(den) > 1e-12) & (t > 1e-9) & (s >= 0) & (s <= 1), t, np.inf)
    k = np.argmin(t, axis=1)
    r = t[np.arange(t.shape[0]), k]
    e_k = walls[k, 2:] - walls[k, :2]
    n_k = np.stack([-e_k[:, 1], e_k[:, 0]], axis=-1) / np.linalg.norm(e_k, axis=1)[:, None]
    cos_inc = np.abs(np.sum(n_k * u[:, 0, :], axis=1))
    return r, np.arccos(np.clip(cos_inc, 0.0, 1.0))


def simulate_beams(
    walls: np.ndarray,
    pose_source: PoseSource,
    head: SonarHead,
    mounting: Mounting,
    *,
    n_beams: int,
    dt_s: float,
    first_bearing_rad: float,
    rng: np.random.Generator,
    return_model: str = "axis",
    range_sigma_m: float = 0.01,
    clutter_prob: float = 0.0,
    t0_s: float = 1000.0,
) -> list[SonarBeam]:
    """Raw 0-255 beams of a head stepping ``head.step_rad`` counter-clockwise in the sonar frame."""
    beams = []
    alpha = head.beam_width_rad
    for k in range(n_beams):
        t = t0_s + k * dt_s
        bearing = first_bearing_rad + k * head.step_rad
        wTs = compose(pose_source.poses([t])[0], mounting.as_pose())
        if return_model == "axis":
            offsets = np.zeros(1)
        elif return_model == "uniform":
            offsets = rng.uniform(-alpha / 2, alpha / 2, 1)
        else:
            offsets = np.linspace(-alpha / 2, alpha / 2, 41)
        r, inc = _ray_hits(wTs[:2], wTs[2] + bearing + offsets, walls)
        r = np.where(inc <= BETA, r, np.inf)
        inten = np.zeros(head.n_bins, dtype=np.uint8)
        r_min = float(r.min())
        if np.isfinite(r_min):
            i = int(np.rint((r_min + rng.normal(0.0, range_sigma_m)) / head.bin_size_m)) - 1
            if 0 <= i < head.n_bins:
                inten[i] = 255
        if rng.random() < clutter_prob:
            inten[rng.integers(0, head.n_bins)] = 150
        angle = float(wrap_angle(bearing)) / head.angle_sense  # as logged: within 2 pi
        beams.append(SonarBeam(t=t, transducer_angle_rad=angle, intensities=inten))
    return beams


def match_lines(lines: list[LineFeature], truth_w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per line: |rho error| and |theta error| to the nearest true wall, in the line's frame R.

    Sign-free: both are normalised lines, compared after normalisation.
    """
    drho, dtheta = [], []
    for ln in lines:
        best = (np.inf, np.inf)
        for lw in truth_w:
            lr = line_world_to_frame(lw, ln.wTr)[0]
            er, et = abs(ln.rho_m - lr[0]), abs(float(wrap_angle(ln.theta_rad - lr[1])))
            if er + 5.0 * et < best[0] + 5.0 * best[1]:
                best = (er, et)
        drho.append(best[0])
        dtheta.append(best[1])
    return np.array(drho), np.array(dtheta)


def run(extractor: LineExtractor, beams: list[SonarBeam]) -> list[LineFeature]:
    lines: list[LineFeature] = []
    for b in beams:
        lines += extractor.add(b)
    return lines + extractor.flush()


# -- the pool test of the paper (section 3) -----------------------------------------------------

POOL_HEAD = SonarHead(n_bins=300, bin_size_m=0.02, step_rad=float(np.deg2rad(0.45)), angle_sense=-1)
POOL_CONFIG = ExtractorConfig(
    sector_deg=270.0,
    incidence_beta_rad=float(BETA),
    min_votes=15,
    min_distance_m=0.2,
    min_range_m=0.3,
    vote_every_n_beams=600,
)
POOL_WALLS = rectangle_walls((-0.18, -0.25), (2.0, 4.0), np.deg2rad(20.0))


def _pool_beams(n_beams: int, first_bearing_deg: float, seed: int) -> list[SonarBeam]:
    return simulate_beams(
        POOL_WALLS,
        ConstantVelocityPoses(),
        POOL_HEAD,
        Mounting(),
        n_beams=n_beams,
        dt_s=0.05,
        first_bearing_rad=np.deg2rad(first_bearing_deg),
        rng=np.random.default_rng(seed),
        range_sigma_m=0.005,
        clutter_prob=0.05,
    )


def _wall_index(lines: list[LineFeature], truth: np.ndarray) -> list[int]:
    return [
        int(
            np.argmin(
                [
                    abs(wrap_angle(ln.line_world()[1] - lw[1])) + abs(ln.line_world()[0] - lw[0])
                    for lw in truth
                ]
            )
        )
        for ln in lines
    ]


@pytest.mark.parametrize("covariance_method", ["fit", "seed"])
def test_pool_all_four_walls(covariance_method: str) -> None:
    """The paper's pool test (section 3): a stationary sonar at (0, 0) in a rotated 2 m x 4 m
    pool, 6 m range, 0.45 deg step, 270 deg sector, beta 25 deg, min votes 15: the four walls,
    and only them. The 270 deg scan starts and ends on the normals of two walls, seen from one
    side only (a 25 deg fan), the weakest geometry of the four."""
    beams = _pool_beams(600, -70.0, seed=2010)
    cfg = POOL_CONFIG.replace(covariance_method=covariance_method)
    poses = ConstantVelocityPoses()
    ex = LineExtractor(cfg, POOL_HEAD, Mounting(), poses)
    lines = run(ex, beams)
    assert ex.n_votes == 1
    assert len(lines) == 4
    truth = wall_lines_world(POOL_WALLS)
    assert sorted(_wall_index(lines, truth)) == [0, 1, 2, 3]
    drho, dtheta = match_lines(lines, truth)
    if covariance_method == "fit":
        assert drho.max() < 0.05
        assert np.rad2deg(dtheta.max()) < 1.0
    else:
        # the seed's line is the centre of its similar-overlap ellipse: rho is as good, theta
        # drifts along the ellipse's long axis on the one-sided walls; the truth stays inside
        assert drho.max() < 0.05
        for ln in lines:
            lw = truth[_wall_index([ln], truth)[0]]
            lr = line_world_to_frame(lw, ln.wTr)[0]
            e = np.array([ln.rho_m - lr[0], float(wrap_angle(ln.theta_rad - lr[1]))])
            assert e @ np.linalg.solve(ln.cov, e) < 9.21  # chi2(0.99, 2 dof)
    for ln in lines:
        assert ln.t == pytest.approx(beams[-1].t, abs=1e-12)
        np.testing.assert_allclose(ln.wTr, [0.0, 0.0, 0.0], atol=1e-12)
        assert ln.cov.shape == (2, 2)
        np.testing.assert_allclose(ln.cov, ln.cov.T, atol=1e-15)
        assert np.all(np.linalg.eigvalsh(ln.cov) > 0.0)
        assert ln.votes >= 15 and ln.n_voters >= 15
        # segment ends lie on the line, inside the pool
        ends = ln.endpoints_r
        n = np.array([np.cos(ln.theta_rad), np.sin(ln.theta_rad)])
        np.testing.assert_allclose(ends @ n, ln.rho_m, atol=1e-9)
        assert np.all(np.abs(ends) < 2.5)
        assert np.linalg.norm(ends[1] - ends[0]) > 0.3


def test_streaming_finds_only_walls() -> None:
    """A turn and a half voting every 40 beams: every line is a wall, every wall is seen, and
    the lines of partly seen walls (short, one-sided fans) stay within their covariance."""
    beams = _pool_beams(1200, 0.0, seed=4)
    poses = ConstantVelocityPoses()
    ex = LineExtractor(POOL_CONFIG.replace(vote_every_n_beams=40), POOL_HEAD, Mounting(), poses)
    lines = run(ex, beams)
    assert ex.n_votes == 1 + (1200 - 600) // 40
    truth = wall_lines_world(POOL_WALLS)
    assert len(lines) >= 4
    assert set(_wall_index(lines, truth)) == {0, 1, 2, 3}
    drho, dtheta = match_lines(lines, truth)
    assert drho.max() < 0.05
    sig_theta = np.array([np.sqrt(ln.cov[1, 1]) for ln in lines])
    assert np.all(dtheta < 4.0 * sig_theta + np.deg2rad(0.2))


# -- motion correction ---------------------------------------------------------------------------

HARBOUR_HEAD = SonarHead(
    n_bins=150, bin_size_m=0.1, step_rad=float(np.deg2rad(0.9)), angle_sense=-1
)
HARBOUR_WALLS = rectangle_walls((1.0, 2.0), (18.0, 24.0), np.deg2rad(-15.0))
MOUNT = Mounting(x_m=0.6, y_m=0.1, yaw_rad=float(np.deg2rad(180.0)), source="test")


def _moving_run(pose_source: PoseSource, truth: ConstantVelocityPoses) -> list[LineFeature]:
    rng = np.random.default_rng(77)
    beams = simulate_beams(
        HARBOUR_WALLS,
        truth,
        HARBOUR_HEAD,
        MOUNT,
        n_beams=400,
        dt_s=0.1,
        first_bearing_rad=np.deg2rad(30.0),
        rng=rng,
        range_sigma_m=0.03,
        t0_s=truth.t0_s,
    )
    cfg = ExtractorConfig(vote_every_n_beams=50, min_votes=12, rho_res_m=0.2)
    return run(LineExtractor(cfg, HARBOUR_HEAD, MOUNT, pose_source), beams)


def test_motion_correction_with_truth_poses_and_blur_without() -> None:
    """A sonar moving at 0.3 m/s and turning 2 deg/s: with the truth pose source every wall is
    right in R; with a pose source that ignores the motion the walls blur."""
    truth = ConstantVelocityPoses(
        start=(-1.0, 1.0, 0.3),
        velocity_mps=(0.25, -0.15),
        yaw_rate_rad_per_s=np.deg2rad(2.0),
        t0_s=500.0,
    )
    walls_w = wall_lines_world(HARBOUR_WALLS)
    good = _moving_run(truth, truth)
    drho, dtheta = match_lines(good, walls_w)
    assert len(good) >= 4
    assert drho.max() < 0.05 and np.rad2deg(dtheta.max()) < 0.3
    # the frozen source gives every beam the last pose: the sector is smeared by the 4 m and
    # 20 deg travelled over it, and so are its lines
    frozen_pose = tuple(truth.poses([truth.t0_s + 399 * 0.1])[0])
    bad = _moving_run(FrozenPoses(frozen_pose), truth)  # type: ignore[arg-type]
    drho_b, _ = match_lines(bad, walls_w)
    assert len(bad) == 0 or np.median(drho_b) > 0.5


# -- uncertainty: consistency of the fit ---------------------------------------------------------


def _single_wall_nees(
    return_model_sim: str, return_model_fit: str, n_runs: int, seed: int
) -> tuple[np.ndarray, np.ndarray]:
    """NEES of the fitted line and its rho errors over Monte Carlo runs of one wall."""
    rng = np.random.default_rng(seed)
    head = SonarHead(n_bins=200, bin_size_m=0.1, step_rad=float(np.deg2rad(0.9)))
    wall = np.array([[12.0, -20.0, 12.0, 20.0]])  # x = 12 m
    truth_w = wall_lines_world(wall)[0]
    sigma_n = 0.03
    cfg = ExtractorConfig(
        sector_deg=180.0,
        min_votes=10,
        vote_every_n_beams=10**6,
        return_model=return_model_fit,
        range_sigma_m=float(np.sqrt(0.1**2 / 12 + sigma_n**2)),
        range_offset_sigma_m=0.0,  # this generator's echoes have no common range offset
    )
    nees, errs = [], []
    for _ in range(n_runs):
        yaw = rng.uniform(-0.3, 0.3)
        poses = ConstantVelocityPoses(start=(rng.uniform(-1, 1), rng.uniform(-1, 1), yaw))
        beams = simulate_beams(
            wall,
            poses,
            head,
            Mounting(),
            n_beams=200,
            dt_s=0.05,
            first_bearing_rad=-np.pi / 2,
            rng=rng,
            return_model=return_model_sim,
            range_sigma_m=sigma_n,
        )
        lines = run(LineExtractor(cfg, head, Mounting(), poses), beams)
        assert len(lines) == 1
        ln = lines[0]
        lr = line_world_to_frame(truth_w, ln.wTr)[0]
        e = np.array([ln.rho_m - lr[0], float(wrap_angle(ln.theta_rad - lr[1]))])
        nees.append(float(e @ np.linalg.solve(ln.cov, e)))
        errs.append(e[0])
    return np.array(nees), np.array(errs)


def test_fit_covariance_is_consistent_when_the_return_model_matches() -> None:
    """Echoes at a uniform bearing within the beam (the fit's noise model): mean NEES ~ 2."""
    nees, _ = _single_wall_nees("uniform", "axis", n_runs=60, seed=1)
    assert 1.2 < nees.mean() < 3.2
    # and for first-return echoes with the first-return model the fit is not biased
    nees_fr, err_fr = _single_wall_nees("first_return", "first_return", n_runs=30, seed=2)
    nees_axis, err_axis = _single_wall_nees("first_return", "axis", n_runs=30, seed=2)
    assert abs(err_fr.mean()) < 0.01
    assert nees_fr.mean() < 3.2
    # the axis model puts a first-return wall too near (by ~ d tan(u) alpha / 2): inconsistent
    assert err_axis.mean() < -0.03
    assert nees_axis.mean() > 10.0


# -- configuration ---------------------------------------------------------------------------------


def test_config_toml_round_trip(tmp_path: Path) -> None:
    cfg = MARINA_FIT
    items = {k: v for k, v in cfg.to_dict().items() if v is not None}

    def fmt(v: object) -> str:
        if isinstance(v, bool):
            return "true" if v else "false"
        if isinstance(v, str):
            return f'"{v}"'
        return repr(v)

    path = tmp_path / "extractor.toml"
    path.write_text("[extractor]\n" + "".join(f"{k} = {fmt(v)}\n" for k, v in items.items()))
    assert ExtractorConfig.from_toml(path) == cfg
    with pytest.raises(ValueError, match="unknown"):
        ExtractorConfig.from_dict({"min_vote": 3})
    path.write_text('[extractor]\nmin_votes = "12"\n')
    with pytest.raises(
        ValueError, match=r"extractor.toml: \[extractor\] min_votes: must be a whole"
    ):
        ExtractorConfig.from_toml(path)  # the file's loader checks types like every other
    with pytest.raises(ValueError):
        ExtractorConfig(covariance_method="ellipse")


def _first_returns_in_a_rectangle(
    n_beams: int, rng: np.random.Generator
) -> tuple[list[SonarBeam], PoseSource, np.ndarray]:
    """First-return beams of the marina head (500 bins of 0.1 m, 1.8 deg, 3 deg beam) from a
    vehicle at constant velocity in a 30 m x 60 m rectangle: the beams, the poses, the walls."""
    head = SonarHead()
    poses = ConstantVelocityPoses(start=(0.0, 0.0, 0.4))
    walls = rectangle_walls((3.0, -2.0), (30.0, 60.0), 0.2)
    raw = simulate_beams(
        walls,
        poses,
        head,
        Mounting(),
        n_beams=n_beams,
        dt_s=0.07,
        first_bearing_rad=0.0,
        rng=rng,
        return_model="first_return",
        range_sigma_m=0.05,
    )
    return raw, poses, walls


def test_marina_preset_on_a_thresholded_mask() -> None:
    """The preset runs on 0/255 masks: the nearest bin of each run votes."""
    rng = np.random.default_rng(8)
    raw, poses, walls = _first_returns_in_a_rectangle(200, rng)
    beams = []
    for b in raw:  # thicken each echo into a 2-3 m run behind the first return, as a mask
        m = b.intensities.copy()
        i = np.flatnonzero(m)
        if i.size:
            m[i[0] : i[0] + int(rng.integers(20, 30))] = 255
        beams.append(SonarBeam(b.t, b.transducer_angle_rad, (m > 0) * np.uint8(255), True))
    lines = run(LineExtractor(MARINA_FIT, SonarHead(), Mounting(), poses), beams)
    assert len(lines) >= 3
    drho, dtheta = match_lines(lines, wall_lines_world(walls))
    assert drho.max() < 0.3 and np.rad2deg(dtheta.max()) < 1.5


def _noisy_raw_beams(n_beams: int, seed: int) -> tuple[list[SonarBeam], PoseSource, np.ndarray]:
    """Raw intensity beams of the marina head in a rectangle: a background of 0-39 in every bin
    and each wall's echo a peak of 230 decaying over 6 bins behind its first return."""
    head = SonarHead()
    rng = np.random.default_rng(seed)
    raw, poses, walls = _first_returns_in_a_rectangle(n_beams, rng)
    beams = []
    for b in raw:
        m = rng.integers(0, 40, head.n_bins).astype(np.uint8)
        i = np.flatnonzero(b.intensities)
        if i.size:
            tail = np.arange(230, 100, -25).astype(np.uint8)[: head.n_bins - i[0]]
            m[i[0] : i[0] + tail.size] = tail
        beams.append(SonarBeam(b.t, b.transducer_angle_rad, m, False))
    return beams, poses, walls


def test_a_mask_preset_on_raw_intensity_beams_is_refused(monkeypatch: pytest.MonkeyPatch) -> None:
    """The keyframes' preset (threshold 1 for 0/255 masks) on raw intensities passes every
    background bin: lines tens of degrees off any wall, silently, without the check; with it,
    a SettingError naming intensity_threshold. The raw beams' preset, and first returns with a
    threshold above the background, are not refused and find the walls."""
    import sonarslam.features.extractor as extractor_module

    beams, poses, walls = _noisy_raw_beams(200, seed=8)
    head, truth_w = SonarHead(), wall_lines_world(walls)
    with monkeypatch.context() as m:  # the check off: the silent wrong answer it prevents
        m.setattr(extractor_module, "MAX_THRESHOLD_PASS_FRACTION", 1.0)
        lines = run(LineExtractor(MARINA_FIT, head, Mounting(), poses), beams)
        _, dtheta = match_lines(lines, truth_w)
        assert np.count_nonzero(np.rad2deg(dtheta) > 20.0) >= 2
    with pytest.raises(
        SettingError,
        match=r"extractor.intensity_threshold: 1 passes 9[0-9] % of the in-range bins of these raw",
    ):
        run(LineExtractor(MARINA_FIT, head, Mounting(), poses), beams)
    for cfg in (EXTRACTOR_PRESETS["default"], MARINA_FIT.replace(intensity_threshold=80.0)):
        for model in ("axis", "first_return"):
            lines = run(
                LineExtractor(cfg.replace(return_model=model), head, Mounting(), poses), beams
            )
            drho, dtheta = match_lines(lines, truth_w)
            assert len(lines) >= 2
            assert drho.max() < 0.3 and np.rad2deg(dtheta.max()) < 2.0, (model, drho, dtheta)


# -- the sector store ------------------------------------------------------------------------------


@dataclass
class MutablePoses:
    """Constant-velocity poses whose offset can be changed after the fact (a smoother)."""

    base: ConstantVelocityPoses
    offset: tuple[float, float, float] = (0.0, 0.0, 0.0)
    growth_per_s: tuple[float, float, float] = (0.0, 0.0, 0.0)

    def poses(self, t_s: npt.ArrayLike) -> np.ndarray:
        return self.base.poses(t_s) + np.asarray(self.offset)

    def covariance(self, t_s: float) -> np.ndarray | None:
        return np.diag(np.asarray(self.growth_per_s) * (t_s - self.base.t0_s))


def _segmented(ranges_bins: list[int]):  # type: ignore[no-untyped-def]
    from sonarslam.sonar.segmentation import SegmentedBeam

    b = np.asarray(ranges_bins, dtype=np.int64)
    return SegmentedBeam(b, b, np.full(b.size, 200, dtype=np.uint8))


@pytest.mark.parametrize("requery", [True, False])
def test_store_ring_buffer_and_motion_correction(requery: bool) -> None:
    from sonarslam.features.geometry import transform_points
    from sonarslam.features.sector import Sector
    from sonarslam.sonar.store import sector_beam_count

    assert sector_beam_count(np.pi, np.deg2rad(0.9)) == 200
    assert sector_beam_count(1.5 * np.pi, np.deg2rad(0.45)) == 600
    head = SonarHead(n_bins=100, bin_size_m=0.1, step_rad=float(np.deg2rad(1.8)))
    truth = ConstantVelocityPoses((1.0, -2.0, 0.5), (0.3, 0.1), 0.05, t0_s=10.0)
    src = MutablePoses(truth)
    mount = Mounting(x_m=0.5, y_m=-0.2, yaw_rad=0.3)
    store = Sector(head, mount, src, sector_rad=np.pi, requery_poses=requery)
    assert store.capacity == 100
    rng = np.random.default_rng(0)
    bins_of = {}
    for k in range(150):
        b = sorted(rng.choice(100, size=int(rng.integers(0, 4)), replace=False).tolist())
        bins_of[k] = b
        store.add(10.0 + 0.1 * k, 0.02 * k, _segmented(b))
    assert len(store) == 100 and store.is_full
    snap = store.snapshot()
    np.testing.assert_allclose(snap.beam_t_s, 10.0 + 0.1 * np.arange(50, 150), atol=1e-9)
    assert len(snap.final) == sum(len(bins_of[k]) for k in range(50, 150))
    # every bin, put back in the world with R, is where its own beam saw it
    wTs = compose(truth.poses(snap.beam_t_s), mount.as_pose())
    np.testing.assert_allclose(snap.wTr, wTs[-1], atol=1e-12)
    k = snap.final.beam
    local = np.stack(
        [
            snap.final.range_m * np.cos(0.02 * (k + 50)),
            snap.final.range_m * np.sin(0.02 * (k + 50)),
        ],
        axis=-1,
    )
    world_direct = transform_points(wTs[k], local)
    world_via_r = transform_points(snap.wTr, snap.final.points_m())
    np.testing.assert_allclose(world_via_r, world_direct, atol=1e-9)
    # a smoother moves the trajectory: re-queried poses follow it, cached ones do not
    src.offset = (0.5, 0.0, 0.1)
    moved = store.snapshot()
    if requery:
        expect = compose(src.poses(snap.beam_t_s), mount.as_pose())
        np.testing.assert_allclose(moved.beam_wTs, expect, atol=1e-9)
        assert np.abs(expect - wTs).max() > 0.4
    else:
        np.testing.assert_allclose(moved.beam_wTs, wTs, atol=1e-12)
    # removal of voters
    assert snap.final.bin_id is not None
    store.remove_final_bins(snap.final.bin_id[::2])
    assert len(store.snapshot().final) == len(snap.final) - len(snap.final.bin_id[::2])
    assert len(store.snapshot().threshold) == len(snap.threshold)


@pytest.mark.parametrize("vote_model", ["arc", "samples"])
def test_vote_models_agree_on_the_pool(vote_model: str) -> None:
    beams = _pool_beams(600, -70.0, seed=5)
    poses = ConstantVelocityPoses()
    cfg = POOL_CONFIG.replace(vote_model=vote_model)
    lines = run(LineExtractor(cfg, POOL_HEAD, Mounting(), poses), beams)
    truth = wall_lines_world(POOL_WALLS)
    assert sorted(_wall_index(lines, truth)) == [0, 1, 2, 3]
    drho, dtheta = match_lines(lines, truth)
    assert drho.max() < 0.05 and np.rad2deg(dtheta.max()) < 1.0


def test_pose_uncertainty_widens_the_covariance() -> None:
    beams = _pool_beams(600, -70.0, seed=6)
    src = MutablePoses(ConstantVelocityPoses(t0_s=1000.0), growth_per_s=(1e-4, 1e-4, 1e-5))
    plain = run(LineExtractor(POOL_CONFIG, POOL_HEAD, Mounting(), src), beams)
    cfg = POOL_CONFIG.replace(pose_uncertainty=True)
    wide = run(LineExtractor(cfg, POOL_HEAD, Mounting(), src), beams)
    assert len(plain) == len(wide) == 4
    for a, b in zip(plain, wide, strict=True):
        assert a.rho_m == pytest.approx(b.rho_m, abs=1e-12)
        d = b.cov - a.cov
        assert np.linalg.eigvalsh(d).min() > -1e-15  # only adds uncertainty
        assert np.trace(d) > 0.1 * np.trace(a.cov)


@dataclass
class GivenCovariance:
    """A still vehicle whose pose source gives ``cov`` as the covariance at every time."""

    cov: np.ndarray

    def poses(self, t_s: npt.ArrayLike) -> np.ndarray:
        return FrozenPoses((0.0, 0.0, 0.0)).poses(t_s)

    def covariance(self, t_s: float) -> np.ndarray | None:
        return self.cov


@dataclass
class GivenCovariances(GivenCovariance):
    """The same, in one call for many times (a BatchCovariances)."""

    def covariances(self, t_s: npt.ArrayLike) -> np.ndarray | None:
        return np.broadcast_to(self.cov, (np.size(t_s), *self.cov.shape))


@pytest.mark.parametrize(
    ("source", "message"),
    [
        (
            GivenCovariance(np.full((3, 3), np.nan)),
            r"covariance\(t\) at t=1\d+\.\d+ s \(Unix\) is not finite",
        ),
        (
            GivenCovariance(np.eye(2) * 1e-4),
            r"covariance\(t\) at t=.* must be \(3, 3\).* got shape \(2, 2\)",
        ),
        (
            GivenCovariance(-np.eye(3) * 1e-4),
            r"covariance\(t\) at .* not positive semi-definite \(least eigenvalue -0.0001\)",
        ),
        (
            GivenCovariance(np.triu(np.ones((3, 3))) * 1e-4),
            r"covariance\(t\) at .* is not symmetric",
        ),
        (
            GivenCovariances(np.eye(2) * 1e-4),
            r"covariances\(t_s\) of \d+ beam times .* must be \(\d+, 3, 3\)",
        ),
        (
            GivenCovariances(-np.eye(3) * 1e-4),
            r"covariances\(t_s\) at .* not positive semi-definite",
        ),
    ],
)
def test_a_pose_covariance_that_is_not_one_is_refused_by_name(
    source: GivenCovariance, message: str
) -> None:
    """With pose_uncertainty, a NaN covariance failed in a bare LinAlgError, a 2x2 one in a
    reshape error, and a negative-definite one was taken; each is refused at the first vote,
    naming the source's method, the time and what a covariance must be."""
    beams = _pool_beams(600, -70.0, seed=6)
    cfg = POOL_CONFIG.replace(pose_uncertainty=True)
    good = GivenCovariance(np.eye(3) * 1e-4)
    assert len(run(LineExtractor(cfg, POOL_HEAD, Mounting(), good), beams)) == 4
    with pytest.raises(ValueError, match=r"the pose source's " + message):
        run(LineExtractor(cfg, POOL_HEAD, Mounting(), source), beams)


def test_pose_uncertainty_widens_the_seed_ellipse_by_the_fit_pose_term() -> None:
    """The seed's ellipse knows nothing of the poses: pose uncertainty adds the fit's pose
    term to it and leaves the line itself alone."""
    beams = _pool_beams(600, -70.0, seed=6)
    src = MutablePoses(ConstantVelocityPoses(t0_s=1000.0), growth_per_s=(1e-4, 1e-4, 1e-5))
    seed_cfg = POOL_CONFIG.replace(covariance_method="seed")
    plain = run(LineExtractor(seed_cfg, POOL_HEAD, Mounting(), src), beams)
    wide = run(
        LineExtractor(seed_cfg.replace(pose_uncertainty=True), POOL_HEAD, Mounting(), src), beams
    )
    fit_plain = run(LineExtractor(POOL_CONFIG, POOL_HEAD, Mounting(), src), beams)
    fit_wide = run(
        LineExtractor(POOL_CONFIG.replace(pose_uncertainty=True), POOL_HEAD, Mounting(), src),
        beams,
    )
    assert len(plain) == len(wide) == len(fit_plain) == len(fit_wide) == 4
    for a, b, fa, fb in zip(plain, wide, fit_plain, fit_wide, strict=True):
        assert (a.rho_m, a.theta_rad) == (b.rho_m, b.theta_rad)
        # the same pose variances up to the voters: the fit refits on its gated support (~30 %)
        np.testing.assert_allclose(np.diag(b.cov - a.cov), np.diag(fb.cov - fa.cov), rtol=0.5)
        assert np.linalg.eigvalsh(b.cov - a.cov).min() > -1e-15


def test_beams_outside_the_pose_sources_span_are_said_once_naming_the_times() -> None:
    """A trajectory that stops halfway through the sector holds its last pose for the rest
    (its design): the extractor says so once, naming the beams' times and the span, those of
    the first vote that met any (it said 300 of 500 as if all); a trajectory over all the beams
    is taken silently. The pool's sonar stands still, so the
    held pose is the true one and the walls are found either way."""
    beams = _pool_beams(800, -70.0, seed=2010)
    t = np.array([b.t for b in beams])
    zero = np.zeros((t.size, 3))
    config = POOL_CONFIG.replace(vote_every_n_beams=40)  # six votes, each past the span
    ex = LineExtractor(config, POOL_HEAD, Mounting(), Trajectory(t[:300], zero[:300]))
    with pytest.warns(PoseSpanWarning) as said:
        lines = run(ex, beams)
    assert ex.n_votes == 6 and len(said) == 1
    message = str(said[0].message)
    assert f"300 beam time(s) {t[300]:.3f}-{t[599]:.3f} s (Unix)" in message  # the first vote's
    assert "the first vote that met any" in message and "later votes may hold more" in message
    assert f"span {t[0]:.3f}-{t[299]:.3f} s" in message
    assert set(_wall_index(lines, wall_lines_world(POOL_WALLS))) == {0, 1, 2, 3}
    whole = LineExtractor(config, POOL_HEAD, Mounting(), Trajectory(t, zero))
    with warnings.catch_warnings():
        warnings.simplefilter("error", PoseSpanWarning)
        assert len(run(whole, beams)) == len(lines)


@dataclass
class DegreePoses:
    """A vehicle turning at ``yaw_rate_rad_per_s`` whose yaw is given in degrees."""

    yaw_rate_rad_per_s: float

    def poses(self, t_s: npt.ArrayLike) -> np.ndarray:
        p = ConstantVelocityPoses(yaw_rate_rad_per_s=self.yaw_rate_rad_per_s).poses(t_s)
        p[:, 2] = np.degrees(p[:, 2])
        return p

    def covariance(self, t_s: float) -> np.ndarray | None:
        return None


def test_a_turning_pose_source_in_degrees_is_refused() -> None:
    """Yaw in degrees on a vehicle turning at 0.3 rad/s (17 deg/s, an ordinary turn) reads as
    17 rad/s between beams 0.05 s apart: refused, naming the beams' times; the same turn in
    radians is taken."""
    beams = _pool_beams(600, -70.0, seed=2010)
    ex = LineExtractor(POOL_CONFIG, POOL_HEAD, Mounting(), DegreePoses(0.3))
    with pytest.raises(ValueError, match=r"yaw jumps from .* between beams at 1000\.\d{3} and"):
        run(ex, beams)
    with pytest.raises(ValueError, match=r"radians \(degrees\?\)"):
        run(LineExtractor(POOL_CONFIG, POOL_HEAD, Mounting(), DegreePoses(0.3)), beams)
    turning = ConstantVelocityPoses(yaw_rate_rad_per_s=0.3)
    run(LineExtractor(POOL_CONFIG, POOL_HEAD, Mounting(), turning), beams)


def test_beams_out_of_order_or_not_in_radians_are_refused_by_name() -> None:
    """Shuffled beams on a turning vehicle were refused as a pose source in degrees; reversed
    beams, beams in degrees (read as radians: no line) and a NaN angle passed silently. Each is
    refused naming ``beam.t`` or ``beam.transducer_angle_rad`` and the beam; the same beams in
    order and in radians are taken (the pool's walls, as in test_pool_all_four_walls)."""
    from dataclasses import replace

    beams = _pool_beams(700, -70.0, seed=2011)
    turning = ConstantVelocityPoses(yaw_rate_rad_per_s=0.3, t0_s=beams[0].t)

    def extractor() -> LineExtractor:
        return LineExtractor(POOL_CONFIG, POOL_HEAD, Mounting(), turning)

    assert len(run(extractor(), beams)) >= 4
    order = np.random.default_rng(7).permutation(len(beams))
    shuffled = [beams[i] for i in order]
    first = next(k for k in range(1, len(order)) if order[k] < order[k - 1])
    with pytest.raises(SettingError, match=rf"^beam\.t: beam {first} at .* is earlier than beam"):
        run(extractor(), shuffled)
    with pytest.raises(SettingError, match=r"^beam\.t: beam 1 at .* time order"):
        run(extractor(), beams[::-1])
    in_degrees = [
        replace(b, transducer_angle_rad=np.degrees(b.transducer_angle_rad)) for b in beams
    ]
    k = next(i for i, b in enumerate(in_degrees) if abs(b.transducer_angle_rad) > 2 * np.pi)
    with pytest.raises(
        SettingError, match=rf"^beam\.transducer_angle_rad: beam {k} at .* degrees or gradians"
    ):
        run(extractor(), in_degrees)
    with_nan = list(beams)
    with_nan[100] = replace(beams[100], transducer_angle_rad=float("nan"))
    with pytest.raises(SettingError, match=r"transducer_angle_rad: beam 100 .* is not a number"):
        run(extractor(), with_nan)
