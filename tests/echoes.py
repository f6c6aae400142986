"""Echo manipulations shared by the tests of the map-sharpness calibrations."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from sonarslam.datasets.records import BeamSeries
from sonarslam.datasets.source import Dataset


def shuffled_echoes(ds: Dataset, seed: int) -> Dataset:
    """The run with its beams' intensity rows permuted among the beams (seeded): echoes with no
    geometry left, so that no sonar yaw or clock offset sharpens their map."""
    b = ds.beams
    assert isinstance(b, BeamSeries)
    rows = np.random.default_rng(seed).permutation(b.intensities.shape[0])
    beams = BeamSeries(b.t_s, b.transducer_angle_rad, b.intensities[rows], b.thresholded)
    return replace(ds, beams=beams)
