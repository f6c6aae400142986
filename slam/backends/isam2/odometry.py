"""The factor graph's odometry between pose nodes, and its averaged AHRS headings.

The graph has a pose node every few seconds (:class:`sonarslam.slam.backends.isam2.graph.LineIsam2`);
between nodes the motion steps (:class:`sonarslam.slam.model.motion.MotionStep`) are integrated by the
motion model (:class:`sonarslam.slam.model.motion.RelativeMotion`) three ways at once:

* since the newest node: the measurement and covariance of the next node's odometry factor
  (with the gyro scale the node started with, no misalignment and no DVL scale error, which
  the factor applies);
* since the newest optimised node: the current pose is that node composed with it;
* the chain ``O(t)`` of the whole run (:class:`sonarslam.slam.model.motion.OdometryChain`): the shape of
  the trajectory between nodes, for the front end's pose source.

The steps' body velocity has the DVL's lever arm compensated at the step's yaw rate
(:func:`sonarslam.slam.model.motion.body_velocity`). The graph has no gyro bias state, so nothing
of that term is estimated; with the gyro scale ``G(0)`` estimated the term stays at the measured
rate (scale 1): its error is ``(s - 1) omega |r|``, the product of the scale's error and the
lever-arm term itself (a 1 m arm turning at 5 deg/s and a 5 % scale error: 4 mm/s), below the
DVL's noise, so the odometry factor's derivative by the scale leaves it out.

AHRS headings taken since the newest node are carried to the next node by the gyro and averaged
into one heading factor (:class:`HeadingMean`), so the graph has one pose per few seconds
instead of one per heading.
"""

from __future__ import annotations

import math

import numpy as np

from sonarslam.features.geometry import FloatArray, wrap_angle
from sonarslam.slam.model.lines import local_to_world
from sonarslam.slam.model.motion import MotionStep, OdometryChain, RelativeMotion, step_displacement

__all__ = ["HeadingMean", "NodeOdometry", "local_covariance"]


def local_covariance(motion: RelativeMotion) -> FloatArray:
    """Covariance of a relative motion in its local tangent (``BetweenFactorPose2``'s)."""
    A = local_to_world(-motion.yaw)
    return A @ motion.cov @ A.T


class HeadingMean:
    """AHRS headings since the last node, carried by the gyro to the next node and averaged.

    A heading ``z_i`` taken when the odometry chain's yaw was ``o_i`` is, at the node (chain yaw
    ``o_n``), ``c_i = z_i - o_i + o_n``; the factor takes their mean. Its variance is the white
    part ``sigma^2 / n`` (added by the caller) plus the gyro's random walk from the samples to
    the node, on average ``f_n - mean(f_i)`` with ``f`` the odometry's yaw variance since the
    previous node. (That gyro part is also in the odometry factor; the correlation is ignored,
    it is small next to the white part.)
    """

    __slots__ = ("n", "_sum", "_ref", "_sum_f")

    def __init__(self) -> None:
        self.reset()

    def reset(self) -> None:
        self.n = 0
        self._sum = self._sum_f = self._ref = 0.0

    def add(self, yaw_meas_rad: float, chain_yaw_rad: float, f_rad2: float) -> None:
        c = yaw_meas_rad - chain_yaw_rad
        if self.n == 0:
            self._ref = c
        self._sum += self._ref + float(wrap_angle(c - self._ref))
        self._sum_f += f_rad2
        self.n += 1

    def at_node(self, chain_yaw_rad: float, f_rad2: float) -> tuple[float, float] | None:
        """Mean heading at the node and the gyro part of its variance, or None if empty."""
        if self.n == 0:
            return None
        z = float(wrap_angle(self._sum / self.n + chain_yaw_rad))
        return z, max(f_rad2 - self._sum_f / self.n, 0.0)


class NodeOdometry:
    """The odometry of :class:`sonarslam.slam.backends.isam2.graph.LineIsam2` (module docstring).

    Parameters
    ----------
    t0_s : float
        Start of the chain (Unix s).
    gyro_sigma_rad_per_s : float
        Yaw-rate noise of the motion model (rad/s).
    dvl_noise : {"hold", "white"}
        How the velocity noise adds up (:class:`sonarslam.slam.backends.isam2.graph.GraphConfig`).
    """

    def __init__(self, t0_s: float, gyro_sigma_rad_per_s: float, dvl_noise: str = "hold") -> None:
        self.gyro_sigma_rad_per_s = gyro_sigma_rad_per_s
        self.dvl_noise = dvl_noise
        self.chain = OdometryChain(t0_s)
        self.since_node = RelativeMotion()
        self.since_anchor = RelativeMotion()
        self.delta_rad = 0.0  # the DVL misalignment used to integrate (the newest estimate)
        self.scale = 1.0  # the gyro scale used to integrate (the newest estimate)
        self.node_scale = 1.0  # the gyro scale of the newest node's start
        self.dvl_gain = 1.0  # 1 + the DVL scale error used to integrate (the newest estimate)
        self.headings = HeadingMean()

    def step(self, step: MotionStep) -> FloatArray:
        """Integrate one motion step; returns the relative motion ``bTb'`` applied."""
        qv = step.var_xy_m2 if self.dvl_noise == "hold" else step.var_xy_white_m2
        qr = step.var_yaw_rad2(self.gyro_sigma_rad_per_s)
        syaw = self.scale * step.dyaw_rad
        # the odometry factor's measurement: delta = 0, the gyro scale of the node's start
        self.since_node.step(step.dx_m, step.dy_m, syaw, qv, qr, step.dyaw_rad)
        sx, sy = self.dvl_gain * step.dx_m, self.dvl_gain * step.dy_m
        if self.delta_rad != 0.0:
            sx, sy = step_displacement(self.delta_rad, sx, sy)
        self.since_anchor.step(sx, sy, syaw, qv, qr)
        rel = np.array([sx, sy, syaw])
        self.chain.append(step.t_s, rel)
        return rel

    def add_heading(self, yaw_body_rad: float) -> None:
        """An AHRS heading, for the next node's heading factor."""
        self.headings.add(yaw_body_rad, float(self.chain.now[2]), self.since_node.f)

    def heading_at_node(self) -> tuple[float, float] | None:
        """The mean heading at a node now and the gyro part of its variance (then reset)."""
        heading = self.headings.at_node(float(self.chain.now[2]), self.since_node.f)
        if heading is not None:
            self.headings.reset()
        return heading

    def start_node(self) -> None:
        """A node was added now: the next factor's motion starts here."""
        self.since_node.reset()
        self.node_scale = self.scale

    def re_anchor(self, delta_rad: float, scale: float, dvl_gain: float = 1.0) -> None:
        """The newest node was optimised: the current pose is it composed with the motion since
        it (rotated by the misalignment and scaled by the DVL gain used so far); integrate with
        the new estimates on."""
        self.since_anchor.copy_from(self.since_node, self.delta_rad, self.dvl_gain)
        self.delta_rad = delta_rad
        self.scale = scale
        self.dvl_gain = dvl_gain

    def carried(self, anchor_xyyaw: tuple[float, float, float]) -> FloatArray:
        """``anchor * (motion since the anchor)``: the current pose, in floats."""
        ax, ay, ayaw = anchor_xyyaw
        m = self.since_anchor
        c, s = math.cos(ayaw), math.sin(ayaw)
        yaw = float(wrap_angle(ayaw + m.yaw))
        return np.array([ax + c * m.x - s * m.y, ay + s * m.x + c * m.y, yaw])

    def carried_covariance(
        self, anchor_yaw_rad: float, anchor_cov_rows: tuple[tuple[float, ...], ...]
    ) -> FloatArray:
        """Covariance of :meth:`carried`: ``J_a S J_a^T + J_b P J_b^T`` of
        :func:`sonarslam.features.geometry.compose_jacobians` with ``S`` the anchor's (rows of floats) and
        ``P`` the motion's since it, in floats (the driver asks for it at every record)."""
        m = self.since_anchor
        c, s = math.cos(anchor_yaw_rad), math.sin(anchor_yaw_rad)
        # J_a = I + u e3^T with u = (-s x - c y, c x - s y, 0)
        u0, u1 = -s * m.x - c * m.y, c * m.x - s * m.y
        (s00, s01, s02), (_, s11, s12), (_, _, s22) = anchor_cov_rows
        a00 = s00 + 2.0 * u0 * s02 + u0 * u0 * s22
        a01 = s01 + u0 * s12 + u1 * s02 + u0 * u1 * s22
        a11 = s11 + 2.0 * u1 * s12 + u1 * u1 * s22
        a02 = s02 + u0 * s22
        a12 = s12 + u1 * s22
        # J_b = blockdiag(R, 1)
        pa, pb, pc, pd, pe = m.a, m.b, m.c, m.d, m.e
        b00 = c * c * pa - 2.0 * c * s * pb + s * s * pc
        b01 = c * s * (pa - pc) + (c * c - s * s) * pb
        b11 = s * s * pa + 2.0 * c * s * pb + c * c * pc
        b02 = c * pd - s * pe
        b12 = s * pd + c * pe
        x00, x01, x11, x02, x12 = a00 + b00, a01 + b01, a11 + b11, a02 + b02, a12 + b12
        return np.array([[x00, x01, x02], [x01, x11, x12], [x02, x12, s22 + m.f]])
