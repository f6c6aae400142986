"""The back ends by name: what ``--backend``, the sweep and the notebooks choose from.

A new back end implements :class:`sonarslam.slam.backends.base.Backend` (for its landmarks, its
``update_lines`` hands :meth:`sonarslam.slam.mapping.landmarks.LandmarkMap.vote` a
:class:`sonarslam.slam.mapping.vote.Belief` and applies the :class:`sonarslam.slam.mapping.vote.Decision` it gets
back), takes a configuration that extends
:class:`sonarslam.slam.backends.base.BackendConfig`, and is added to :data:`BACKENDS` here; the runner,
the CLI's ``--set``, the sweep's grid and the reports then take it as they take these two.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from sonarslam.features.geometry import FloatArray
from sonarslam.slam.backends.base import Backend, BackendConfig
from sonarslam.slam.backends.ekf import EkfConfig, LineEkf
from sonarslam.slam.backends.isam2.graph import GraphConfig, LineIsam2
from sonarslam.sonar.beam import Mounting

__all__ = ["BackendSpec", "BACKENDS", "backend_spec"]


@dataclass(frozen=True)
class BackendSpec:
    """A SLAM back end the closed loop can run.

    Attributes
    ----------
    name : str
        Its ``--backend`` name, also the scope of its ``--set`` settings.
    config_type : type
        Its frozen configuration dataclass (default-constructible).
    make : callable
        ``(t0_s, wTb0 (3,), P0 (3, 3), sonar_mounting, config) -> Backend``.
    smoother : bool
        It has a smoothed trajectory and a final batch optimisation (``--batch``).
    summary : str
        One line for ``--help``.
    """

    name: str
    config_type: type[BackendConfig]
    make: Callable[[float, FloatArray, FloatArray, Mounting, BackendConfig], Backend]
    smoother: bool
    summary: str


def _maker(
    backend: Callable[[float, FloatArray, FloatArray, Mounting, Any], Backend],
    config_type: type[BackendConfig],
) -> Callable[[float, FloatArray, FloatArray, Mounting, BackendConfig], Backend]:
    """A ``make`` that refuses a configuration of another back end."""

    def make(
        t0_s: float, wTb0: FloatArray, P0: FloatArray, mounting: Mounting, config: BackendConfig
    ) -> Backend:
        if not isinstance(config, config_type):
            raise TypeError(f"{config_type.__name__} expected, got {type(config).__name__}")
        return backend(t0_s, wTb0, P0, mounting, config)

    return make


BACKENDS: dict[str, BackendSpec] = {
    "ekf": BackendSpec(
        "ekf", EkfConfig, _maker(LineEkf, EkfConfig), False, "EKF-SLAM with line landmarks"
    ),
    "isam2": BackendSpec(
        "isam2",
        GraphConfig,
        _maker(LineIsam2, GraphConfig),
        True,
        "GTSAM iSAM2 factor graph with line landmarks",
    ),
}


def backend_spec(name: str) -> BackendSpec:
    """The back end called ``name``; ValueError naming the known ones otherwise."""
    if name not in BACKENDS:
        raise ValueError(f"unknown back end {name!r}; one of {sorted(BACKENDS)}")
    return BACKENDS[name]
