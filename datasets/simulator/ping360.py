"""A simulated run as a Blue Robotics Ping360 would log it: the beams as a Ping Viewer ``.bin``
(:func:`sonarslam.datasets.ping360.write_ping360_log`), the navigation as a ROS 1 bag, with the
defects of a field log (:class:`Ping360Defects`).

The scenario's head is made Ping360-shaped (:func:`ping360_head`): whole gradians of step, a
whole number of 25 ns ticks of sample period at :data:`~sonarslam.datasets.ping360.SPEED_OF_SOUND_MPS`,
200-1200 samples, the Ping360's 2 deg beam. So the beams read back from the ``.bin`` are the
simulated ones: the intensities and the stamps (whole ms, as the simulator makes them) exactly,
the angles to the simulator's rounding of its angles to 1e-6 rad (the ``.bin`` holds whole
gradians).

The defects, as Ping Viewer writes them (:class:`Ping360Defects`): records split mid-message (a
record is what the serial link read at once), the file name and stamps in another script's
digits (a Persian-locale Windows), the range changed in the first seconds (Ping Viewer opens
at 2 m; each such beam rendered anew at its range, 1200 samples of Ping Viewer's sample
period, :func:`range_head`), and no navigation at all.

Files written in ``out_dir``:

=================================  ==========================================================
``yyyyMMdd-hhmmsszzz.bin``         the beams (named by the log's start, UTC, 0.5 s before
                                   the first beam; stamps elapsed since then)
``nav.bag``                        DVL, IMU and GPS (:func:`sonarslam.datasets.rosbag.write_bag`;
                                   its sonar topic is empty); not with ``nav=False``
``sonarslam.toml``                 the scenario's calibration and ``[ping360] nav = "nav.bag"``
                                   (without ``[sonar] n_bins``, ``bin_size_m`` when the range
                                   changes: the log's segments give them)
``truth.json``                     the simulator's ground truth, with ``ping360_log``: the
                                   beams written, those whose bytes were lost, the segments
=================================  ==========================================================
"""

from __future__ import annotations

import json
import math
import tempfile
import warnings
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from sonarslam.datasets.config import dump_dataset_config
from sonarslam.datasets.dataset import Dataset
from sonarslam.datasets.errors import DataWarning
from sonarslam.datasets.ping360 import (
    PING360_BEAM_WIDTH_DEG,
    SPEED_OF_SOUND_MPS,
    TICK_S,
    log_file_name,
    sample_spacing_m,
    write_ping360_log,
)
from sonarslam.datasets.rosbag import write_bag
from sonarslam.datasets.simulator.msis import render_intensities
from sonarslam.datasets.simulator.scenario import Simulation, make_scenario, simulate_records
from sonarslam.datasets.simulator.writer import drop_gps, write_dataset
from sonarslam.datasets.source import open_dataset
from sonarslam.settings import bounded, check_fields
from sonarslam.sonar.beam import SonarHead

__all__ = [
    "PING360_SAMPLES",
    "PERSIAN_ZERO",
    "Ping360Defects",
    "ping360_head",
    "range_head",
    "write_ping360_run",
    "simulate_ping360",
]

#: The Ping360's sample counts (``number_of_samples``, ping-protocol).
PING360_SAMPLES = (200, 1200)
#: The zero of the Extended Arabic-Indic digits a Persian-locale Windows writes (U+06F0).
PERSIAN_ZERO = "\u06f0"
_GRAD_RAD = math.pi / 200.0
#: The simulator's angles are rounded to 1e-6 rad; one further from whole gradians is not a
#: Ping360's (rad).
_GRAD_TOL_RAD = 1e-5
#: The log opens this long before its first beam (ms).
_LEAD_MS = 500


@dataclass(frozen=True)
class Ping360Defects:
    """The defects of a field log written into a simulated ``.bin`` (module docstring).

    Attributes
    ----------
    split_records : bool
        Cut the messages' bytes into records as Ping Viewer's serial link delivers them
        (``write_ping360_log``'s ``split_rng``); False: a message a record.
    zero_digit : str
        The zero of the digits of the file name and the stamps: ``"0"``, or
        :data:`PERSIAN_ZERO`.
    first_ranges_m : tuple of float
        The log starts at these ranges (m), each for ``first_range_s`` of beams, before the
        head's own (2 and 15 m: Ping Viewer opens at 2 m and the user sets the range).
    first_range_s : float
        How long each of ``first_ranges_m`` lasts (s).
    lose_every : int
        Every this many beams, one loses the middle third of its bytes on the link (a message
        cut short); 0 none.
    nav : bool
        Write the navigation (``nav.bag`` and ``[ping360] nav``); False: a sonar log alone.
    """

    split_records: bool = True
    zero_digit: str = "0"
    first_ranges_m: tuple[float, ...] = ()
    first_range_s: float = bounded(3.0, 0.0, 3600.0, low_open=True)
    lose_every: int = bounded(0, 0, 10**9)
    nav: bool = True

    def __post_init__(self) -> None:
        check_fields(self)
        for r in self.first_ranges_m:
            if not 0.75 <= r <= 100.0:
                raise ValueError(f"a Ping360's range is 0.75-100 m, got {r:g}")


def ping360_head(head: SonarHead) -> SonarHead:
    """``head`` made Ping360-shaped: its bin size the nearest whole number of 25 ns ticks at
    1500 m/s, its step the nearest whole gradians (at least one), its bins 200-1200, a 2 deg
    beam."""
    ticks = max(int(round(2.0 * head.bin_size_m / (SPEED_OF_SOUND_MPS * TICK_S))), 1)
    step_grad = max(int(round(head.step_rad / _GRAD_RAD)), 1)
    lo, hi = PING360_SAMPLES
    return replace(
        head,
        n_bins=min(max(head.n_bins, lo), hi),
        bin_size_m=sample_spacing_m(ticks, SPEED_OF_SOUND_MPS),
        step_rad=step_grad * _GRAD_RAD,
        beam_width_rad=math.radians(PING360_BEAM_WIDTH_DEG),
    )


def range_head(head: SonarHead, range_m: float) -> SonarHead:
    """``head`` at ``range_m`` as Ping Viewer sets a range (``Ping360::set_range`` and
    ``calculateSamplePeriod`` of ping-viewer 1ed4508): 1200 samples, the sample period
    ``2 range / (1200 c 25 ns)`` truncated to whole ticks, fewer samples where that period
    would be under the firmware's 80 ticks."""
    n = PING360_SAMPLES[1]
    ticks = int(2.0 * range_m / (n * SPEED_OF_SOUND_MPS * TICK_S))
    while ticks < 80:
        n -= 1
        ticks = int(2.0 * range_m / (n * SPEED_OF_SOUND_MPS * TICK_S))
    return replace(head, n_bins=n, bin_size_m=sample_spacing_m(ticks, SPEED_OF_SOUND_MPS))


def _sample_period_ticks(head: SonarHead) -> int:
    ticks = int(round(2.0 * head.bin_size_m / (SPEED_OF_SOUND_MPS * TICK_S)))
    if ticks < 1 or sample_spacing_m(ticks, SPEED_OF_SOUND_MPS) != head.bin_size_m:
        raise ValueError(
            f"bin size {head.bin_size_m} m is not a whole number of 25 ns ticks at"
            f" {SPEED_OF_SOUND_MPS:g} m/s (ping360_head)"
        )
    return ticks


def _first_ranges(
    d: Dataset, sim: Simulation | None, defects: Ping360Defects
) -> tuple[np.ndarray, np.ndarray, np.ndarray, list[dict[str, Any]]]:
    """Each beam's samples (rows as wide as the most), sample period and sample count, the
    first seconds' beams rendered anew at :attr:`Ping360Defects.first_ranges_m`; and the
    segments in words for ``truth.json``."""
    head = d.config.sonar
    beams = d.beams
    heads = [range_head(head, r) for r in defects.first_ranges_m]
    width = max([head.n_bins, *(h.n_bins for h in heads)])
    rows = np.zeros((len(beams), width), np.uint8)
    rows[:, : head.n_bins] = beams.intensities
    ticks = np.full(len(beams), _sample_period_ticks(head))
    counts = np.full(len(beams), head.n_bins)
    t = beams.t_s - d.config.sonar_time_offset_s
    segments = []
    start = float(t[0])
    for k, h in enumerate([*heads, head]):
        t0 = start + k * defects.first_range_s
        last = k == len(heads)
        inside = np.flatnonzero((t >= t0) & ((t < t0 + defects.first_range_s) | last))
        if not last and inside.size:
            if sim is None:
                raise ValueError("the first ranges' beams are rendered anew: give the simulation")
            rng = np.random.default_rng([sim.scenario.seed, 41, k])
            true_t = np.array([sim.beams[i].t for i in inside])
            rows[inside, : h.n_bins] = render_intensities(
                sim.world,
                h,
                sim.scenario.sonar_mounting,
                sim.trajectory.poses(true_t),
                beams.transducer_angle_rad[inside],
                rng,
                sim.scenario.echo,
            )
            rows[inside, h.n_bins :] = 0
            ticks[inside] = _sample_period_ticks(h)
            counts[inside] = h.n_bins
        if inside.size:
            segments.append(
                {"beams": int(inside.size), "n_bins": h.n_bins, "bin_size_m": h.bin_size_m}
            )
    return rows, ticks, counts, segments


def _toml_without_head_size(toml: str) -> str:
    """A ``sonarslam.toml``'s text without ``[sonar] n_bins`` and ``bin_size_m``."""
    out, table = [], ""
    for line in toml.splitlines():
        if line.startswith("["):
            table = line.strip()
        if table == "[sonar]" and line.split("=")[0].strip() in ("n_bins", "bin_size_m"):
            continue
        out.append(line)
    return "\n".join(out) + "\n"


def write_ping360_run(
    d: Dataset,
    out_dir: str | Path,
    layout: Path | None = None,
    defects: Ping360Defects | None = None,
    sim: Simulation | None = None,
) -> Path:
    """Write a dataset of a Ping360-shaped head as a ``.bin`` and a navigation bag (module
    docstring); ``layout``: the folder whose ``truth.json`` goes with it; ``defects``: the
    field log's (default :class:`Ping360Defects`: split records only); ``sim``: the
    simulation (its world and trajectory render the first ranges' beams anew). Returns the
    ``.bin``.

    Raises
    ------
    ValueError
        A head or beams a Ping360 cannot log: a bin size that is not whole ticks, angles off
        whole gradians, a run longer than a day.
    """
    defects = defects or Ping360Defects()
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    rows, ticks, counts, segments = _first_ranges(d, sim, defects)
    beams = d.beams.shifted(-d.config.sonar_time_offset_s)
    angle = np.mod(beams.transducer_angle_rad, 2.0 * math.pi)
    grads = np.rint(angle / _GRAD_RAD).astype(np.int64)
    miss = np.abs(angle - grads * _GRAD_RAD)
    if miss.size and float(miss.max()) > _GRAD_TOL_RAD:
        raise ValueError(f"a beam angle {float(miss.max()):.2e} rad off whole gradians")
    t_ms = np.rint(beams.t_s * 1000.0).astype(np.int64)
    start_ms = int(t_ms[0]) - _LEAD_MS
    stamps = t_ms - start_ms
    if stamps[-1] >= 86_400_000:
        raise ValueError("a Ping Viewer log's stamps cover a day at most")
    seed = sim.scenario.seed if sim is not None else 0
    lose = tuple(range(defects.lose_every // 2, len(beams), defects.lose_every or len(beams) + 1))
    log = write_ping360_log(
        out / log_file_name(start_ms, defects.zero_digit),
        stamps,
        grads % 400,
        rows,
        ticks,
        n_samples=counts,
        split_rng=np.random.default_rng([seed, 360]) if defects.split_records else None,
        zero=defects.zero_digit,
        lose=lose if defects.lose_every else (),
    )
    toml = dump_dataset_config(d.config)
    if defects.first_ranges_m:
        toml = _toml_without_head_size(toml)
    if defects.nav:
        write_bag(replace(d, beams=d.beams[:0]), out / "nav.bag", "ros1")
        toml += f'\n[ping360]\nnav = "nav.bag"\nspeed_of_sound_mps = {SPEED_OF_SOUND_MPS}\n'
    else:
        toml += f"\n[ping360]\nspeed_of_sound_mps = {SPEED_OF_SOUND_MPS}\n"
    (out / "sonarslam.toml").write_text(toml, encoding="utf-8")
    if layout is not None and (layout / "truth.json").is_file():
        truth = json.loads((layout / "truth.json").read_text(encoding="utf-8"))
        truth["ping360_log"] = {
            "beams": len(beams),
            "lost_beams": list(lose) if defects.lose_every else [],
            "segments": segments,
        }
        (out / "truth.json").write_text(json.dumps(truth, allow_nan=False) + "\n", "utf-8")
    return log


def simulate_ping360(
    kind: str,
    seed: int,
    out_dir: str | Path,
    duration_s: float | None = None,
    gps: bool = True,
    defects: Ping360Defects | None = None,
) -> Path:
    """Simulate ``kind`` with a Ping360-shaped head (:func:`ping360_head` of its own) and write
    it as a ``.bin`` with its navigation bag (module docstring), with a GPS topic unless
    ``gps`` is False, with ``defects`` (default: split records only). Returns the ``.bin``."""
    scenario = make_scenario(kind, seed, duration_s)
    scenario = replace(scenario, head=ping360_head(scenario.head))
    sim = simulate_records(scenario)
    with tempfile.TemporaryDirectory() as tmp:
        layout = write_dataset(sim, Path(tmp) / "run")
        if not gps:
            drop_gps(layout)
        with warnings.catch_warnings():  # the sensors' gaps are the simulator's own
            warnings.simplefilter("ignore", DataWarning)
            dataset = open_dataset(layout)
        return write_ping360_run(dataset, out_dir, layout, defects, sim)
