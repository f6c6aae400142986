"""The front end's lines in your own EKF, filterpy's (docs/api.md, example 3)."""

import numpy as np
from filterpy.kalman import ExtendedKalmanFilter

import sonarslam
from sonarslam.features.geometry import between, compose, compose_jacobians, line_difference

ds = sonarslam.open_dataset(sonarslam.simulate("harbour", 0, "sim-harbour", duration_s=120.0))
odometry = sonarslam.dead_reckoning_trajectory(ds)  # your odometry: here the DVL and the AHRS
beams = ds.nav_beams().between(*odometry.span_s)  # the beams it has poses for
bTs = ds.config.sonar_mounting.as_pose()  # the sonar in the body frame (x_m, y_m, yaw_rad)
extractor = sonarslam.LineExtractor(
    sonarslam.extractor_preset(ds), ds.config.sonar, ds.config.sonar_mounting, odometry
)
association = sonarslam.LandmarkAssociation(bTs, seeds_used=False)  # one line makes a landmark


def new_filter(x: np.ndarray, P: np.ndarray) -> ExtendedKalmanFilter:
    """State [x_m, y_m, yaw_rad, rho_0, theta_0, ...]; filterpy's size is fixed: one per size."""
    ekf = ExtendedKalmanFilter(dim_x=x.size, dim_z=2)
    ekf.x, ekf.P = x, P
    return ekf


def h(x: np.ndarray, j: int) -> np.ndarray:  # landmark j seen from the pose: (rho_m, theta_rad)
    return sonarslam.line_prediction(x[:3], x[3 + 2 * j : 5 + 2 * j], bTs)[0]


def H(x: np.ndarray, j: int) -> np.ndarray:  # its Jacobian, (2, n)
    _, H_pose, H_line = sonarslam.line_prediction(x[:3], x[3 + 2 * j : 5 + 2 * j], bTs)
    out = np.zeros((2, x.size))
    out[:, :3], out[:, 3 + 2 * j : 5 + 2 * j] = H_pose, H_line
    return out


def belief() -> sonarslam.WorldBelief:
    return sonarslam.WorldBelief(ekf.x[:3], ekf.x[3:].reshape(-1, 2), ekf.P)


t_k = float(odometry.t_s[0])
ekf = new_filter(odometry.poses(t_k)[0], np.diag([1.0, 1.0, 0.05**2]))
for beam in beams:
    lines = extractor.add(beam)  # a vote's lines, in the sonar frame at the newest beam
    if not lines:
        continue
    u = between(*odometry.poses([t_k, lines[0].t]))  # predict: the odometry's step (body frame)
    J_pose, J_u = compose_jacobians(ekf.x[:3], u)
    F = np.eye(ekf.x.size)
    F[:3, :3] = J_pose
    ekf.x[:3] = compose(ekf.x[:3], u)
    ekf.P = F @ ekf.P @ F.T
    ekf.P[:3, :3] += J_u @ np.diag([(0.05 + 0.05 * np.hypot(*u[:2])) ** 2] * 2 + [1e-4]) @ J_u.T
    t_k = lines[0].t
    decision = association.decide(lines, belief())  # merges: none by default
    for j, line in decision.updates:
        residual = lambda a, b: line_difference(a, b)[0]  # noqa: E731  # the sign of rho free
        ekf.update(line.z, H, h, line.cov, args=(j,), hx_args=(j,), residual=residual)
    for new in decision.new_landmarks:  # augment with the newest line, and its correlations
        obs = sonarslam.world_observation(new.observations[-1][1], ekf.x[:3], ekf.P[:3, :3], bTs)
        n = ekf.x.size
        P = np.zeros((n + 2, n + 2))
        P[:n, :n], P[n:, n:] = ekf.P, obs.cov_w
        P[n:, :n] = obs.G_pose @ ekf.P[:3, :]
        P[:n, n:] = P[n:, :n].T
        ekf = new_filter(np.concatenate([ekf.x, obs.line_w]), P)
    association.applied(belief())  # the estimate after the update, before the next vote

final = belief()
print(f"{final.k} landmarks")
