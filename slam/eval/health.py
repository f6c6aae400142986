"""The health monitor: is a run still consistent with its own model? GPS-free, both back ends.

A closed loop can go wrong without failing: a gyro bias that the model leaves out is taken for
the AHRS bias's walk, the heading spins, every wall becomes a new landmark, and the run ends
with exit 0 and numbers that look like numbers. The monitor reads what a run already logs and
flags what the model says cannot happen (Bar-Shalom, Li & Kirubarajan 2001, sec. 5.4: the
innovations of a consistent filter are white with the covariance it predicts):

``nis_<kind>``
    The NIS of the heading, line and scan updates, in groups of ``nis_window_updates``
    consecutive updates: a group is flagged when even the lower confidence bound of its median
    NIS is beyond ``nis_scale_max`` times the chi2 median (the innovations are that many times their predicted variance). A
    median with a bound, not a mean: the association gate truncates the line NIS, and one
    outlier must not flag a window. A group whose upper confidence bound of the median is
    below ``nis_scale_min`` times the chi2 median is *under-confident*: a finding, not an issue
    (below).
``nees``
    Simulated runs only (the simulator's truth, never GPS): the pose NEES of the estimate's own
    samples (:func:`sonarslam.slam.eval.consistency.nees_series`, chi2(3) when consistent) in
    windows of ``window_s``; a window is flagged when its median NEES is beyond
    ``chi2.ppf(1 - false_alarm / (2 W), 3)`` over ``W`` windows. The samples of a window are
    strongly correlated (one error drifts slowly), so no independence is assumed: a median beyond
    ``c`` needs half the samples beyond it, whose chance is at most twice that of one sample
    (Markov's inequality on their count), hence the 2. A window whose median NEES is below
    ``chi2.ppf(false_alarm / (2 W), 3)`` (the same argument on the lower tail) is
    *under-confident*: a finding, not an issue.
``departure``
    The estimate against dead reckoning (the same sensors without the corrections): the
    squared Mahalanobis distance of their positions with the *sum* of the two covariances
    (which they share the odometry of, so the sum is the cautious bound), against chi2(2).
``heading_bias``
    The AHRS heading minus the estimate's: the bias the estimate implies, beyond
    ``bias_sigmas`` times its prior sigma (with the walk's growth) over a window.
``state``
    The back end's final constants (AHRS bias, DVL misalignment and scale) beyond
    ``bias_sigmas`` times their prior sigma, and pose covariances that are not positive
    definite.
``landmarks``
    Landmark count growth: a window in which at least ``landmark_min_new`` landmarks were
    created and they are more than ``landmark_new_share_max`` of the window's associations
    (a map that re-observes its walls associates far more lines than it creates landmarks).
    The first window is not judged: the map starts empty, and every wall seen then is new.
``travel``
    The direction the vehicle travels in its own frame by dead reckoning (the DVL's velocities
    through its mounting, :func:`travel_direction`): judged when at least
    ``travel_min_share`` of the travel goes one way, flagged beyond ``travel_max_angle_deg``
    off the bow. A vehicle travels bow first; a DVL mounting turned the wrong way round moves
    it stern- or side-first, and the map is as sharp with the sonar's yaw turned alike, so no
    other check sees it (docs/research/calibration.md).
``odometry``
    Every closed loop, with GPS or without: the sonar's motion between nearby scans
    against dead reckoning's (:func:`sonarslam.slam.eval.loops.odometry_check`), flagged when they disagree by more than
    :data:`sonarslam.slam.eval.loops.ODOMETRY_MAX_ANGLE_DEG` (a sensor mounted the wrong way
    round: :attr:`sonarslam.slam.eval.loops.OdometryCheck.turned`).
``lines``
    The line extractor's yield: a run of at least ``lines_min_beams`` beams that gave fewer
    than ``min_lines_per_kbeam`` lines per 1000 beams is dead reckoning that no check above
    can see (no line, no innovation to judge). Its likely causes: beam angles in another unit
    than radians, an ``intensity_threshold`` above the echoes, a ``max_range_m`` or head range
    short of the walls. The marina and simulated runs give 7-13 lines per 1000 beams
    (docs/bad-input.md).

The chance thresholds are Bonferroni-corrected over a check's windows, so that a consistent
run raises a check with probability at most ``false_alarm``. :func:`assess` gives a
:class:`HealthReport`: its issues (check, cause, time span), ``health_*`` figures for
``metrics.json``, one warning per issue, and a line for the report.

Only overconfidence is an issue: an estimate that believes itself better than it is misleads
every gate after it. The opposite, innovations or errors far *smaller* than their predicted
covariance (a told noise too large, or a prediction that already holds the measurement it is
compared with), is reported as a distinct *under-confident* finding (``HealthReport.findings``,
``health_underconfident``): it wastes information but misleads no gate, so it neither warns nor
makes the run unhealthy.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy.stats import binom, chi2

from sonarslam.datasets.errors import DataWarning
from sonarslam.features.geometry import FloatArray, wrap_angle
from sonarslam.settings import bounded, check_fields
from sonarslam.slam.eval.consistency import nees_series, window_median_gate
from sonarslam.slam.eval.loops import LOOP_CAUSES, ODOMETRY_CAUSES, OdometryCheck
from sonarslam.slam.io.trajectory import Trajectory

__all__ = [
    "HealthConfig",
    "NisStream",
    "StateValue",
    "HealthInputs",
    "HealthIssue",
    "HealthReport",
    "assess",
    "median_lower_bound",
    "median_upper_bound",
    "travel_direction",
    "travel_judgement",
    "travel_cause",
]


@dataclass(frozen=True)
class HealthConfig:
    """Thresholds of the health monitor (see the module docstring).

    Attributes
    ----------
    window_s : float
        Length of the windows the NIS, heading and landmark checks judge (s).
    false_alarm : float
        Probability that one check flags a consistent run (its windows' tests together).
    min_updates : int
        Fewest updates of a kind for its NIS to be judged.
    nis_window_updates : int
        The NIS is judged in groups of this many consecutive updates (a window of time would
        hold a handful of line updates when the walls are far apart, too few to judge).
    nis_scale_max : float
        Largest factor by which the innovations may exceed their predicted variance.
    nis_scale_min : float
        A group of innovations whose median NIS is, with confidence, below this fraction of the
        chi2 median is under-confident (a finding, not an issue).
    bias_sigmas : float
        A constant beyond this many prior sigmas is not a bias of the model.
    landmark_min_new : int
        Fewest landmarks created in a window for the growth check.
    landmark_new_share_max : float
        Largest share of new landmarks among a window's associations and creations.
    min_lines_per_kbeam : float
        Fewest lines per 1000 beams of a run the ``lines`` check judges.
    lines_min_beams : int
        Fewest beams for the ``lines`` check to judge a run.
    travel_max_angle_deg : float
        Largest angle off the bow of the vehicle's travel in its own frame (deg): halfway to
        the nearest wrong way round of a mounting (a multiple of 90 deg).
    travel_min_share : float
        The ``travel`` check judges a run whose travel goes this much one way (the resultant
        share of :func:`travel_direction`; a vehicle that hovers or goes every way says
        nothing).
    """

    window_s: float = bounded(120.0, 1.0, 1e5)
    false_alarm: float = bounded(0.01, 1e-9, 0.5)
    min_updates: int = bounded(10, 3, 10_000)
    nis_window_updates: int = bounded(40, 3, 100_000)
    nis_scale_max: float = bounded(1.5, 1.0, 1e3)
    nis_scale_min: float = bounded(1.0 / 3.0, 1e-6, 1.0)
    bias_sigmas: float = bounded(10.0, 1.0, 1e3)
    landmark_min_new: int = bounded(5, 1, 10_000)
    landmark_new_share_max: float = bounded(0.5, 0.0, 1.0)
    min_lines_per_kbeam: float = bounded(1.0, 0.0, 1e3)
    lines_min_beams: int = bounded(2000, 1, 10**9)
    travel_max_angle_deg: float = bounded(45.0, 1.0, 180.0)
    travel_min_share: float = bounded(0.5, 0.0, 1.0)

    def __post_init__(self) -> None:
        check_fields(self)


@dataclass(frozen=True)
class NisStream:
    """The NIS of one kind of update: times (K,) Unix s, values (K,), its degrees of freedom,
    and the probability of the gate the updates passed (None: not gated)."""

    kind: str
    t_s: FloatArray
    nis: FloatArray
    dof: int
    gate_probability: float | None = None


@dataclass(frozen=True)
class StateValue:
    """A constant of the back end's state at the end of the run, with its prior sigma (same
    unit) and its unit for the message."""

    name: str
    value: float
    prior_sigma: float
    unit: str


@dataclass(frozen=True)
class HealthInputs:
    """What a run logged, as the monitor reads it.

    Attributes
    ----------
    trajectory : Trajectory
        The causal estimate with covariances.
    reference : Trajectory or None
        Dead reckoning from the same sensors, with covariances.
    ahrs_t_s, ahrs_yaw_rad : ndarray, shape (M,)
        The AHRS body headings the back end was given (Unix s, rad).
    ahrs_bias_sigma_rad, ahrs_bias_walk_rad_per_sqrt_s : float
        The model's prior sigma of the AHRS bias and its walk.
    nis : list of NisStream
    landmark_created_s : ndarray, shape (L,)
        When each landmark was created (Unix s).
    reobserved_s : ndarray, shape (A,)
        When a line was associated with an existing landmark (Unix s).
    states : list of StateValue
    truth : Trajectory or None
        The simulator's true poses (simulated runs only): the ``nees`` check.
    n_beams, n_lines : int
        The beams the extractor was given and the lines it gave (the ``lines`` check; not
        judged with ``n_beams`` 0).
    travel_body_mps : ndarray, shape (V, 2)
        Dead reckoning's velocities in the body frame (m/s; the DVL's rows with bottom lock
        through its mounting): the ``travel`` check (not judged without rows).
    odometry : OdometryCheck or None
        The run's odometry check (every closed loop's): the ``odometry`` check.
    mountings_said : str
        The mountings those two checks blame, as configured, in words (their values and
        sources), appended to their issues.
    """

    trajectory: Trajectory
    reference: Trajectory | None
    ahrs_t_s: FloatArray
    ahrs_yaw_rad: FloatArray
    ahrs_bias_sigma_rad: float
    ahrs_bias_walk_rad_per_sqrt_s: float
    nis: Sequence[NisStream] = ()
    landmark_created_s: FloatArray = field(default_factory=lambda: np.zeros(0))
    reobserved_s: FloatArray = field(default_factory=lambda: np.zeros(0))
    states: Sequence[StateValue] = ()
    truth: Trajectory | None = None
    n_beams: int = 0
    n_lines: int = 0
    travel_body_mps: FloatArray = field(default_factory=lambda: np.zeros((0, 2)))
    odometry: OdometryCheck | None = None
    mountings_said: str = ""


@dataclass(frozen=True)
class HealthIssue:
    """One inconsistency: the check, its cause in words, the time span (Unix s)."""

    check: str
    cause: str
    t0_s: float
    t1_s: float

    def message(self, t_ref_s: float) -> str:
        span = f"{self.t0_s - t_ref_s:.0f}-{self.t1_s - t_ref_s:.0f} s"
        return f"health: {self.check} at {span} into the run: {self.cause}"


@dataclass
class HealthReport:
    """The monitor's verdict.

    Attributes
    ----------
    issues : list of HealthIssue
        Each inconsistency found, in order.
    judged : dict of str to int
        Per check, how many windows (or states) it judged.
    t_ref_s : float
        The estimate's first time (Unix s): issue messages give times from it.
    config : HealthConfig
        The limits the checks used.
    findings : list of HealthIssue
        Each under-confident window (NIS or NEES far below its band), in order: reported, not
        an inconsistency (the module docstring).
    """

    issues: list[HealthIssue]
    judged: dict[str, int]
    t_ref_s: float
    config: HealthConfig
    findings: list[HealthIssue] = field(default_factory=list)

    @property
    def ok(self) -> bool:
        return not self.issues

    def checks_flagged(self) -> list[str]:
        return sorted({i.check for i in self.issues})

    def checks_underconfident(self) -> list[str]:
        return sorted({i.check for i in self.findings})

    def metrics(self) -> dict[str, Any]:
        """``health_*`` keys of ``metrics.json``."""
        out: dict[str, Any] = {
            "health_ok": self.ok,
            "health_issues": len(self.issues),
            "health_flagged": self.checks_flagged(),
            "health_false_alarm": self.config.false_alarm,
        }
        for check, n in sorted(self.judged.items()):
            out[f"health_{check}_windows"] = n
            out[f"health_{check}_flagged"] = sum(i.check == check for i in self.issues)
            out[f"health_{check}_underconfident"] = sum(i.check == check for i in self.findings)
        out["health_first_issue"] = self.issues[0].message(self.t_ref_s) if self.issues else None
        out["health_underconfident"] = self.checks_underconfident()
        out["health_first_finding"] = (
            self.findings[0].message(self.t_ref_s) if self.findings else None
        )
        return out

    def warn(self) -> None:
        """One counted :class:`DataWarning` per issue."""
        for issue in self.issues:
            warnings.warn(issue.message(self.t_ref_s), DataWarning, stacklevel=2)

    def line(self) -> str:
        """One line for the report; the under-confident checks after it, marked as such."""
        if self.ok:
            n = sum(self.judged.values())
            out = (
                f"health: no inconsistency found in the online loop ({n} windows and states"
                f" judged, each check at"
                f" a {100 * self.config.false_alarm:g} % false-alarm rate)"
            )
        else:
            counts = [(c, sum(i.check == c for i in self.issues)) for c in self.checks_flagged()]
            out = (
                f"health: {len(self.issues)} inconsistencies in the online loop"
                f" ({', '.join(c if k == 1 else f'{c} x{k}' for c, k in counts)});"
                f" first: {self.issues[0].message(self.t_ref_s).removeprefix('health: ')}"
            )
        if self.findings:
            out += (
                f"; under-confident, not an error: {', '.join(self.checks_underconfident())}"
                f" ({len(self.findings)} spans)"
            )
        return out


def median_lower_bound(values: FloatArray, alpha: float) -> float:
    """A one-sided lower confidence bound, at level ``1 - alpha``, of the median of the
    distribution ``values`` are drawn from: the order statistic ``x_(k)`` with
    ``P(Binomial(n, 1/2) < k) <= alpha`` (distribution-free); ``-inf`` when ``n`` is too small."""
    x = np.sort(np.asarray(values, dtype=np.float64))
    n = x.size
    k = int(binom.ppf(alpha, n, 0.5))  # P(B <= k - 1) <= alpha < P(B <= k)
    while k > 0 and binom.cdf(k - 1, n, 0.5) > alpha:
        k -= 1
    if k < 1:
        return -math.inf
    return float(x[k - 1])


def median_upper_bound(values: FloatArray, alpha: float) -> float:
    """A one-sided upper confidence bound, at level ``1 - alpha``, of the median of the
    distribution ``values`` are drawn from: :func:`median_lower_bound` of the negated values,
    negated (``+inf`` when ``n`` is too small)."""
    return -median_lower_bound(-np.asarray(values, dtype=np.float64), alpha)


def _windows(t0_s: float, t1_s: float, window_s: float) -> FloatArray:
    """Window edges covering ``[t0, t1]`` (Unix s), shape (W + 1,)."""
    n = max(int(math.ceil((t1_s - t0_s) / window_s)), 1)
    return np.asarray(t0_s + window_s * np.arange(n + 1), dtype=np.float64)


def _spans(
    edges: FloatArray, flagged: np.ndarray, end_s: float = math.inf
) -> list[tuple[float, float, np.ndarray]]:
    """Runs of flagged windows as ``(t0, t1, window indices)``; ``t1`` no later than ``end_s``,
    the end of what the windows hold (the last window runs past it)."""
    out: list[tuple[float, float, np.ndarray]] = []
    idx = np.flatnonzero(flagged)
    if idx.size == 0:
        return out
    groups = np.split(idx, np.flatnonzero(np.diff(idx) > 1) + 1)
    for g in groups:
        out.append((float(edges[g[0]]), min(float(edges[g[-1] + 1]), end_s), g))
    return out


def _groups(n: int, size: int) -> list[np.ndarray]:
    """Consecutive groups of ``size`` indices of ``range(n)``; a last group shorter than half
    of it joins the one before."""
    edges = list(range(0, n, size)) + [n]
    if len(edges) > 2 and edges[-1] - edges[-2] < size // 2:
        edges.pop(-2)
    return [np.arange(a, b) for a, b in zip(edges[:-1], edges[1:], strict=True)]


def _check_nis(
    stream: NisStream, cfg: HealthConfig
) -> tuple[list[HealthIssue], int, list[HealthIssue]]:
    """Groups of ``nis_window_updates`` consecutive updates whose median NIS is, with
    confidence, beyond ``nis_scale_max`` chi2 medians (issues); or below ``nis_scale_min``
    of it (under-confident findings)."""
    p = stream.gate_probability
    # the median of chi2(dof) truncated at the gate: the quantile p / 2 of the untruncated one
    median = float(chi2.ppf(0.5 if p is None else p / 2.0, stream.dof))
    order = np.argsort(stream.t_s, kind="stable")
    t, nis = stream.t_s[order], stream.nis[order]
    if t.size < cfg.min_updates:
        return [], 0, []
    groups = _groups(t.size, cfg.nis_window_updates)
    alpha = cfg.false_alarm / len(groups)
    flagged = np.zeros(len(groups), dtype=bool)
    cautious = np.zeros(len(groups), dtype=bool)
    medians = np.zeros(len(groups))
    for w, g in enumerate(groups):
        medians[w] = float(np.median(nis[g]))
        flagged[w] = median_lower_bound(nis[g], alpha) > cfg.nis_scale_max * median
        cautious[w] = median_upper_bound(nis[g], alpha) < cfg.nis_scale_min * median
    edges = np.array([t[g[0]] for g in groups] + [t[-1]])
    issues = []
    for _, _, run in _spans(edges, flagged):
        worst = run[int(np.argmax(medians[run]))]
        issues.append(
            HealthIssue(
                f"nis_{stream.kind}",
                f"{stream.kind} innovations too large: median NIS {medians[worst]:.2f} over"
                f" {groups[worst].size} updates (chi2({stream.dof}) median {median:.2f}; limit"
                f" {cfg.nis_scale_max:g}x)",
                float(t[groups[run[0]][0]]),
                float(t[groups[run[-1]][-1]]),
            )
        )
    findings = []
    for _, _, run in _spans(edges, cautious):
        least = run[int(np.argmin(medians[run]))]
        findings.append(
            HealthIssue(
                f"nis_{stream.kind}",
                f"{stream.kind} innovations smaller than predicted: median NIS"
                f" {medians[least]:.3f} over {groups[least].size} updates (chi2({stream.dof})"
                f" median {median:.2f}; under-confident below {cfg.nis_scale_min:.3g}x): a told"
                " noise too large, or a prediction that already holds the measurement",
                float(t[groups[run[0]][0]]),
                float(t[groups[run[-1]][-1]]),
            )
        )
    return issues, len(groups), findings


def _check_nees(
    trajectory: Trajectory, truth: Trajectory, cfg: HealthConfig
) -> tuple[list[HealthIssue], int, list[HealthIssue]]:
    """Windows whose median pose NEES against the truth is beyond the Bonferroni-corrected
    chi2(3) gate, doubled for correlated samples (issues), or below the same lower gate
    (under-confident findings; module docstring)."""
    series = nees_series(trajectory, truth, "pose")
    t, values = series.t_s, series.nees
    ok = np.isfinite(values)
    t, values = t[ok], values[ok]
    if t.size < cfg.min_updates:
        return [], 0, []
    edges = _windows(float(t[0]), float(t[-1]), cfg.window_s)
    which = np.clip(np.searchsorted(edges, t, side="right") - 1, 0, edges.size - 2)
    present = np.unique(which)
    gate = window_median_gate(series.dof, int(present.size), cfg.false_alarm)
    medians = np.full(edges.size - 1, -np.inf)
    for w in present:
        medians[w] = float(np.median(values[which == w]))
    # the lower gate: a median below c needs half the samples below it (chance <= 2 F(c))
    low = float(chi2.ppf(cfg.false_alarm / (2.0 * present.size), series.dof))
    issues = []
    for a, b, g in _spans(edges, medians > gate, float(t[-1])):
        worst = g[int(np.argmax(medians[g]))]
        issues.append(
            HealthIssue(
                "nees",
                f"the pose error is beyond its covariance: median NEES {medians[worst]:.1f}"
                f" against the truth in the worst {cfg.window_s:g} s window (chi2({series.dof}) median"
                f" {chi2.ppf(0.5, series.dof):.2f}; limit {gate:.1f})",
                max(a, float(t[0])),
                min(b, float(t[-1])),
            )
        )
    findings = []
    cautious = np.isfinite(medians) & (medians < low)
    for a, b, g in _spans(edges, cautious, float(t[-1])):
        least = g[int(np.argmin(medians[g]))]
        findings.append(
            HealthIssue(
                "nees",
                f"the pose error is far within its covariance: median NEES {medians[least]:.3f}"
                f" against the truth in the least {cfg.window_s:g} s window (chi2({series.dof}) median"
                f" {chi2.ppf(0.5, series.dof):.2f}; under-confident below {low:.3f})",
                max(a, float(t[0])),
                min(b, float(t[-1])),
            )
        )
    return issues, int(present.size), findings


def _check_departure(
    trajectory: Trajectory, reference: Trajectory, cfg: HealthConfig
) -> tuple[list[HealthIssue], int]:
    """Spans where the estimate's position leaves dead reckoning's beyond their covariances."""
    assert trajectory.covs is not None and reference.covs is not None
    t = trajectory.t_s
    lo, hi = reference.span_s
    inside = (t >= lo) & (t <= hi)
    t = t[inside]
    if t.size == 0:
        return [], 0
    d = trajectory.poses_wTb[inside, :2] - reference.poses(t)[:, :2]
    j = np.clip(np.searchsorted(reference.t_s, t, side="right") - 1, 0, reference.t_s.size - 1)
    S = trajectory.covs[inside, :2, :2] + reference.covs[j, :2, :2]
    d2 = np.einsum("ni,ni->n", d, np.linalg.solve(S, d[:, :, None])[:, :, 0])
    edges = _windows(float(t[0]), float(t[-1]), cfg.window_s)
    n_windows = edges.size - 1
    gate = float(chi2.ppf(1.0 - cfg.false_alarm / n_windows, 2))
    which = np.clip(np.searchsorted(edges, t, side="right") - 1, 0, n_windows - 1)
    worst = np.full(n_windows, -np.inf)
    np.maximum.at(worst, which, d2)
    issues = []
    for a, b, g in _spans(edges, worst > gate, float(t[-1])):
        k = int(np.argmax(np.where(np.isin(which, g), d2, -np.inf)))
        issues.append(
            HealthIssue(
                "departure",
                f"the estimate is {float(np.hypot(*d[k])):.1f} m from dead reckoning, squared"
                f" Mahalanobis distance {d2[k]:.1f} with both covariances (limit {gate:.1f})",
                max(a, float(t[0])),
                min(b, float(t[-1])),
            )
        )
    return issues, n_windows


def _check_heading_bias(inputs: HealthInputs, cfg: HealthConfig) -> tuple[list[HealthIssue], int]:
    """Windows where the AHRS heading minus the estimate's (the bias the estimate implies) is
    beyond ``bias_sigmas`` prior sigmas, the walk's growth included."""
    tr = inputs.trajectory
    lo, hi = tr.span_s
    keep = (inputs.ahrs_t_s >= lo) & (inputs.ahrs_t_s <= hi)
    t = inputs.ahrs_t_s[keep]
    if t.size == 0:
        return [], 0
    # unwrapped: a heading that spins away from the AHRS is thousands of degrees off
    r = np.unwrap(wrap_angle(inputs.ahrs_yaw_rad[keep] - tr.poses(t)[:, 2]))
    sigma = np.sqrt(
        inputs.ahrs_bias_sigma_rad**2 + inputs.ahrs_bias_walk_rad_per_sqrt_s**2 * (t - lo)
    )
    edges = _windows(lo, hi, cfg.window_s)
    which = np.clip(np.searchsorted(edges, t, side="right") - 1, 0, edges.size - 2)
    flagged = np.zeros(edges.size - 1, dtype=bool)
    med = np.zeros(edges.size - 1)
    lim = np.zeros(edges.size - 1)
    for w in np.unique(which):
        m = which == w
        med[w] = float(np.median(r[m]))
        lim[w] = cfg.bias_sigmas * float(np.max(sigma[m]))
        flagged[w] = abs(med[w]) > lim[w]
    issues = []
    for a, b, g in _spans(edges, flagged, hi):
        worst = g[int(np.argmax(np.abs(med[g])))]
        issues.append(
            HealthIssue(
                "heading_bias",
                f"the AHRS heading is {np.rad2deg(med[worst]):.1f} deg off the estimate's"
                f" (limit {np.rad2deg(lim[worst]):.1f} deg: {cfg.bias_sigmas:g} prior sigmas of"
                " the AHRS bias)",
                max(a, lo),
                min(b, hi),
            )
        )
    return issues, int(np.unique(which).size)


def _check_states(inputs: HealthInputs, cfg: HealthConfig) -> tuple[list[HealthIssue], int]:
    """Final constants beyond ``bias_sigmas`` prior sigmas; covariances not positive definite."""
    lo, hi = inputs.trajectory.span_s
    issues = []
    for s in inputs.states:
        if s.prior_sigma > 0.0 and not abs(s.value) <= cfg.bias_sigmas * s.prior_sigma:
            issues.append(
                HealthIssue(
                    "state",
                    f"the final {s.name} is {s.value:.4g} {s.unit}, beyond {cfg.bias_sigmas:g}"
                    f" times its prior sigma {s.prior_sigma:.4g} {s.unit}",
                    lo,
                    hi,
                )
            )
    covs = inputs.trajectory.covs
    if covs is not None and covs.size:
        sym = np.abs(covs - np.swapaxes(covs, 1, 2)).max(axis=(1, 2))
        scale = np.abs(covs).max(axis=(1, 2))
        ok = np.all(np.isfinite(covs), axis=(1, 2)) & (sym <= 1e-6 * np.maximum(scale, 1e-300))
        eig = np.full(covs.shape[0], -np.inf)
        eig[ok] = np.linalg.eigvalsh(covs[ok]).min(axis=1)
        bad = eig <= 0.0
        if bad.any():
            t = inputs.trajectory.t_s
            i = np.flatnonzero(bad)
            issues.append(
                HealthIssue(
                    "state",
                    f"{i.size} pose covariances are not positive definite (first smallest"
                    f" eigenvalue {eig[i[0]]:.3g})",
                    float(t[i[0]]),
                    float(t[i[-1]]),
                )
            )
    return issues, len(inputs.states) + 1


def _check_landmarks(inputs: HealthInputs, cfg: HealthConfig) -> tuple[list[HealthIssue], int]:
    """Windows that create many landmarks and re-observe few."""
    lo, hi = inputs.trajectory.span_s
    edges = _windows(lo, hi, cfg.window_s)
    n = edges.size - 1

    def count(t: FloatArray) -> np.ndarray:
        w = np.searchsorted(edges, t, side="right") - 1
        return np.bincount(w[(w >= 0) & (w < n)], minlength=n)

    new = count(inputs.landmark_created_s)
    again = count(inputs.reobserved_s)
    share = new / np.maximum(new + again, 1)
    judged = new >= cfg.landmark_min_new
    judged[0] = False  # the map starts empty: every wall of the first window is new
    flagged = judged & (share > cfg.landmark_new_share_max)
    issues = []
    for a, b, g in _spans(edges, flagged, hi):
        issues.append(
            HealthIssue(
                "landmarks",
                f"{int(new[g].sum())} landmarks created against {int(again[g].sum())}"
                f" re-observations (share {new[g].sum() / max(new[g].sum() + again[g].sum(), 1):.2f},"
                f" limit {cfg.landmark_new_share_max:g}): the map does not re-find its walls"
                f" ({LOOP_CAUSES})",
                a,
                b,
            )
        )
    return issues, int(judged.sum())


def _check_lines(inputs: HealthInputs, cfg: HealthConfig) -> tuple[list[HealthIssue], int]:
    """A run of many beams that gave (almost) no line, with its likely causes."""
    n_beams, n_lines = inputs.n_beams, inputs.n_lines
    if n_beams < cfg.lines_min_beams:
        return [], 0
    if 1000.0 * n_lines / n_beams >= cfg.min_lines_per_kbeam:
        return [], 1
    lo, hi = inputs.trajectory.span_s
    cause = (
        f"{n_lines} lines from {n_beams} beams (fewer than {cfg.min_lines_per_kbeam:g} per 1000):"
        " the run is dead reckoning. Likely causes: beam angles not in radians (gradians or"
        " degrees), extractor.intensity_threshold above the echoes, extractor.max_range_m or"
        " the head's range short of the walls"
    )
    return [HealthIssue("lines", cause, lo, hi)], 1


def travel_direction(v_body_mps: FloatArray) -> tuple[float, float]:
    """Which way a vehicle travels in its own frame.

    Parameters
    ----------
    v_body_mps : ndarray, shape (V, 2)
        Velocities in the body frame (m/s; x forward, y left).

    Returns
    -------
    angle_rad : float
        The angle of the summed velocities from the bow (rad, counter-clockwise, range
        ``[-pi, pi]``); NaN when they sum to zero.
    share : float
        The resultant share ``|sum v| / sum |v|`` (0-1): 1 when every row goes one way, near 0
        for a vehicle that goes every way or hovers; NaN without motion.
    """
    v = np.asarray(v_body_mps, dtype=np.float64).reshape(-1, 2)
    total = float(np.sum(np.hypot(v[:, 0], v[:, 1])))
    if not total > 0.0:
        return math.nan, math.nan
    sx, sy = (float(a) for a in v.sum(axis=0))
    share = math.hypot(sx, sy) / total
    return (math.atan2(sy, sx) if share > 0.0 else math.nan), share


def travel_judgement(v_body_mps: FloatArray, cfg: HealthConfig) -> tuple[float, float, bool, bool]:
    """:func:`travel_direction` judged: ``(angle_rad, share, judged, off_bow)``, ``judged`` when
    at least ``cfg.travel_min_share`` of the travel goes one way, ``off_bow`` when it is then
    more than ``cfg.travel_max_angle_deg`` off the bow."""
    angle, share = travel_direction(v_body_mps)
    judged = share >= cfg.travel_min_share  # NaN (no motion): not judged
    return angle, share, judged, judged and abs(math.degrees(angle)) > cfg.travel_max_angle_deg


def travel_cause(v_body_mps: FloatArray, cfg: HealthConfig) -> tuple[str | None, bool]:
    """The ``travel`` check on dead reckoning's body-frame velocities (V, 2) (m/s): ``(cause,
    judged)``, the cause in words when the vehicle moves far off its bow (module docstring),
    else None."""
    if v_body_mps.shape[0] < cfg.min_updates:
        return None, False
    angle, share, judged, off_bow = travel_judgement(v_body_mps, cfg)
    if not off_bow:
        return None, judged
    return (
        f"dead reckoning moves the vehicle {math.degrees(angle):+.0f} deg off its bow ({share:.2f}"
        f" of its travel one way in its own frame; limit {cfg.travel_max_angle_deg:g} deg): a"
        " vehicle travels bow first, so the DVL's mounting ([mounting.dvl] yaw_deg, or its axes'"
        " signs) is likely turned by about that; a sonar yaw calibrated by map sharpness on this"
        " dead reckoning (`sonarslam calibrate`) took the same turn: calibrate it again after"
        " the fix. A vehicle that truly travels stern- or side-first: not an error"
    ), True


def _check_travel(inputs: HealthInputs, cfg: HealthConfig) -> tuple[list[HealthIssue], int]:
    """Dead reckoning that moves the vehicle far off its bow (:func:`travel_cause`)."""
    cause, judged = travel_cause(inputs.travel_body_mps, cfg)
    if cause is None:
        return [], int(judged)
    lo, hi = inputs.trajectory.span_s
    if inputs.mountings_said:
        cause += f" (now: {inputs.mountings_said})"
    return [HealthIssue("travel", cause, lo, hi)], 1


def _check_odometry(inputs: HealthInputs) -> tuple[list[HealthIssue], int]:
    """The sonar's motion turned far from dead reckoning's (module docstring)."""
    check = inputs.odometry
    if check is None or not check.accepted:
        return [], 0
    if not check.turned:
        return [], 1
    lo, hi = inputs.trajectory.span_s
    cause = (
        f"the sonar sees the vehicle move {check.heading_deg:+.0f} deg away from where dead"
        f" reckoning moves it ({check.accepted} registrations of scans a few metres apart,"
        f" standard error {check.heading_se_deg:.1f} deg): one of {ODOMETRY_CAUSES} is likely"
        " wrong; every estimate of this run follows dead reckoning's motion"
        + (f" (now: {inputs.mountings_said})" if inputs.mountings_said else "")
    )
    return [HealthIssue("odometry", cause, lo, hi)], 1


def assess(inputs: HealthInputs, config: HealthConfig | None = None) -> HealthReport:
    """Run every check on a run's logs (module docstring); the issues in time order."""
    cfg = config or HealthConfig()
    lo, _ = inputs.trajectory.span_s
    issues: list[HealthIssue] = []
    findings: list[HealthIssue] = []
    judged: dict[str, int] = {}
    for stream in inputs.nis:
        found, n, cautious = _check_nis(stream, cfg)
        issues += found
        findings += cautious
        judged[f"nis_{stream.kind}"] = n
    if inputs.truth is not None and inputs.trajectory.covs is not None:
        found, judged["nees"], cautious = _check_nees(inputs.trajectory, inputs.truth, cfg)
        issues += found
        findings += cautious
    if inputs.reference is not None and inputs.trajectory.covs is not None:
        if inputs.reference.covs is not None:
            found, judged["departure"] = _check_departure(inputs.trajectory, inputs.reference, cfg)
            issues += found
    found, judged["heading_bias"] = _check_heading_bias(inputs, cfg)
    issues += found
    found, judged["state"] = _check_states(inputs, cfg)
    issues += found
    found, judged["landmarks"] = _check_landmarks(inputs, cfg)
    issues += found
    found, n = _check_lines(inputs, cfg)
    if n:
        judged["lines"] = n
    issues += found
    found, n = _check_travel(inputs, cfg)
    if n:
        judged["travel"] = n
    issues += found
    found, n = _check_odometry(inputs)
    if n:
        judged["odometry"] = n
    issues += found
    issues.sort(key=lambda i: (i.t0_s, i.check))
    findings.sort(key=lambda i: (i.t0_s, i.check))
    return HealthReport(issues, judged, lo, cfg, findings)
