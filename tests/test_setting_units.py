"""The units `info` prints beside each setting come from the setting's name (slam.run.settings)."""

from __future__ import annotations

import pytest

from sonarslam.slam.backends.registry import BACKENDS
from sonarslam.slam.run.presets import backend_config
from sonarslam.slam.run.settings import unit_of


@pytest.mark.parametrize(
    ("name", "unit"),
    [
        ("ekf.gyro_bias_sigma_deg_per_s", "deg/s"),
        ("noise.ahrs_bias_walk_deg_per_sqrt_s", "deg/sqrt(s)"),
        ("gates.ahrs_max_rate_deg_per_s", "deg/s"),
        ("isam2.node_period_s", "s"),
        ("noise.dvl_sigma_mps", "m/s"),
        ("extractor.min_votes", ""),
    ],
)
def test_a_setting_s_unit_is_read_from_its_name(name: str, unit: str):
    assert unit_of(name) == unit


def test_every_rate_setting_of_the_back_ends_is_in_a_rate_unit():
    """No `_per_s` setting is shown in seconds (the suffix `_s` must not win over it)."""
    rates = [
        field
        for backend in BACKENDS
        for field in vars(backend_config(backend))
        if field.endswith("_per_s") and not field.endswith("_per_sqrt_s")
    ]
    assert rates  # the EKF's gyro bias sigma at least
    for field in rates:
        assert unit_of(field).endswith("/s"), field
