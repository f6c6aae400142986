"""A simulated run as a Blue Robotics Ping360 would log it: the beams as a Ping Viewer ``.bin``
(:func:`sonarslam.datasets.ping360.write_ping360_log`), the navigation as a ROS 1 bag.

The scenario's head is made Ping360-shaped (:func:`ping360_head`): whole gradians of step, a
whole number of 25 ns ticks of sample period at :data:`~sonarslam.datasets.ping360.SPEED_OF_SOUND_MPS`,
200-1200 samples, the Ping360's 2 deg beam. So the beams read back from the ``.bin`` are the
simulated ones: the intensities and the stamps (whole ms, as the simulator makes them) exactly,
the angles to the simulator's rounding of its angles to 1e-6 rad (the ``.bin`` holds whole
gradians).

Files written in ``out_dir``:

=================================  ==========================================================
``yyyyMMdd-hhmmsszzz.bin``         the beams (named by the log's start, UTC, 0.5 s before
                                   the first beam; stamps elapsed since then)
``nav.bag``                        DVL, IMU and GPS (:func:`sonarslam.datasets.rosbag.write_bag`;
                                   its sonar topic is empty)
``sonarslam.toml``                 the scenario's calibration and ``[ping360] nav = "nav.bag"``
``truth.json``                     the simulator's ground truth
=================================  ==========================================================
"""

from __future__ import annotations

import math
import shutil
import tempfile
import warnings
from dataclasses import replace
from pathlib import Path

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
from sonarslam.datasets.simulator.scenario import make_scenario, simulate_records
from sonarslam.datasets.simulator.writer import drop_gps, write_dataset
from sonarslam.datasets.source import open_dataset
from sonarslam.sonar.beam import SonarHead

__all__ = ["PING360_SAMPLES", "ping360_head", "write_ping360_run", "simulate_ping360"]

#: The Ping360's sample counts (``number_of_samples``, ping-protocol).
PING360_SAMPLES = (200, 1200)
_GRAD_RAD = math.pi / 200.0
#: The simulator's angles are rounded to 1e-6 rad; one further from whole gradians is not a
#: Ping360's (rad).
_GRAD_TOL_RAD = 1e-5
#: The log opens this long before its first beam (ms).
_LEAD_MS = 500


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


def _sample_period_ticks(head: SonarHead) -> int:
    ticks = int(round(2.0 * head.bin_size_m / (SPEED_OF_SOUND_MPS * TICK_S)))
    if ticks < 1 or sample_spacing_m(ticks, SPEED_OF_SOUND_MPS) != head.bin_size_m:
        raise ValueError(
            f"bin size {head.bin_size_m} m is not a whole number of 25 ns ticks at"
            f" {SPEED_OF_SOUND_MPS:g} m/s (ping360_head)"
        )
    return ticks


def write_ping360_run(d: Dataset, out_dir: str | Path, layout: Path | None = None) -> Path:
    """Write a dataset of a Ping360-shaped head as a ``.bin`` and a navigation bag (module
    docstring); ``layout``: the folder whose ``truth.json`` goes with it. Returns the ``.bin``.

    Raises
    ------
    ValueError
        A head or beams a Ping360 cannot log: a bin size that is not whole ticks, angles off
        whole gradians, a run longer than a day.
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    ticks = _sample_period_ticks(d.config.sonar)
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
    log = write_ping360_log(
        out / log_file_name(start_ms), stamps, grads % 400, beams.intensities, ticks
    )
    write_bag(replace(d, beams=d.beams[:0]), out / "nav.bag", "ros1")
    toml = dump_dataset_config(d.config) + (
        f'\n[ping360]\nnav = "nav.bag"\nspeed_of_sound_mps = {SPEED_OF_SOUND_MPS}\n'
    )
    (out / "sonarslam.toml").write_text(toml, encoding="utf-8")
    if layout is not None and (layout / "truth.json").is_file():
        shutil.copy(layout / "truth.json", out / "truth.json")
    return log


def simulate_ping360(
    kind: str,
    seed: int,
    out_dir: str | Path,
    duration_s: float | None = None,
    gps: bool = True,
) -> Path:
    """Simulate ``kind`` with a Ping360-shaped head (:func:`ping360_head` of its own) and write
    it as a ``.bin`` with its navigation bag (module docstring), with a GPS topic unless
    ``gps`` is False. Returns the ``.bin``."""
    scenario = make_scenario(kind, seed, duration_s)
    scenario = replace(scenario, head=ping360_head(scenario.head))
    with tempfile.TemporaryDirectory() as tmp:
        layout = write_dataset(simulate_records(scenario), Path(tmp) / "run")
        if not gps:
            drop_gps(layout)
        with warnings.catch_warnings():  # the sensors' gaps are the simulator's own
            warnings.simplefilter("ignore", DataWarning)
            dataset = open_dataset(layout)
        return write_ping360_run(dataset, out_dir, layout)
