"""The front end's lines as factors in your own iSAM2 graph (docs/api.md, example 2)."""

import gtsam
from gtsam.symbol_shorthand import L, X

import sonarslam

ds = sonarslam.open_dataset(sonarslam.simulate("harbour", 0, "sim-harbour", duration_s=120.0))
odometry = sonarslam.dead_reckoning_trajectory(ds)  # your odometry: here the DVL and the AHRS
beams = ds.nav_beams().between(*odometry.span_s)  # the beams it has poses for
bTs = ds.config.sonar_mounting.as_pose()  # the sonar in the body frame (x_m, y_m, yaw_rad)
extractor = sonarslam.LineExtractor(
    sonarslam.extractor_preset(ds), ds.config.sonar, ds.config.sonar_mounting, odometry
)
association = sonarslam.LandmarkAssociation(bTs, seeds_used=True)  # a factor per observation


def pose(t_s: float) -> gtsam.Pose2:
    return gtsam.Pose2(*odometry.poses(t_s)[0])


def belief(k: int, marginals: gtsam.ISAM2 | None = None) -> sonarslam.WorldBelief:
    # the pose X(k) and every landmark of the association, landmark j's line at L(j)
    return sonarslam.gtsam_belief(isam.calculateEstimate(), X(k), L, association, marginals)


isam, graph, values = gtsam.ISAM2(), gtsam.NonlinearFactorGraph(), gtsam.Values()
k, t_k = 0, float(odometry.t_s[0])
graph.add(gtsam.PriorFactorPose2(X(0), pose(t_k), gtsam.noiseModel.Diagonal.Sigmas([1, 1, 0.05])))
values.insert(X(0), pose(t_k))
for lines in filter(None, map(extractor.add, beams)):  # each vote's lines (frame R)
    step = pose(t_k).between(pose(lines[0].t))  # a pose node per vote, and the odometry to it
    sigma_m = 0.05 + 0.05 * (step.x() ** 2 + step.y() ** 2) ** 0.5  # 5 cm + 5 % of the step
    noise = gtsam.noiseModel.Diagonal.Sigmas([sigma_m, sigma_m, 0.01])
    graph.add(gtsam.BetweenFactorPose2(X(k), X(k + 1), step, noise))
    values.insert(X(k + 1), pose(lines[0].t))  # its first guess: the odometry's pose
    isam.update(graph, values)  # with X(0)'s prior the first time
    k, t_k, graph, values = k + 1, lines[0].t, gtsam.NonlinearFactorGraph(), gtsam.Values()
    decision = association.decide(lines, belief(k, isam), pose_key=X(k))  # no merges by default
    for j, line in decision.updates:  # an observation of landmark j
        graph.add(sonarslam.line_factor(X(k), L(j), line))  # its z, cov and mounting
    for new in decision.new_landmarks:  # with every observation that made it, at its pose
        values.insert(L(new.id), new.line_w)
        for anchor, line in new.observations:
            graph.add(sonarslam.line_factor(anchor.node, L(new.id), line))
    isam.update(graph, values)
    association.applied(belief(k))  # the estimate after the update, before the next vote
    graph, values = gtsam.NonlinearFactorGraph(), gtsam.Values()

final = belief(k)
print(f"{k} poses, {final.k} landmarks")
