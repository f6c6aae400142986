"""The front end alone on a simulated run, with the simulator's true poses (docs/api.md, example 1)."""

import math

import sonarslam

sim = sonarslam.simulate_records(sonarslam.make_scenario("harbour", seed=0, duration_s=60.0))
head, mounting = sim.scenario.head, sim.scenario.sonar_mounting
extractor = sonarslam.LineExtractor(
    sonarslam.extractor_preset("default"),  # the raw beams' preset
    head,
    mounting,
    sim.trajectory,  # the PoseSource: the vehicle's pose at any beam time
)
lines = [line for beam in sim.beams for line in extractor.add(beam)]  # one beam at a time
for line in lines:  # (rho, theta) in the sonar frame of the vote, with its covariance
    s_rho, s_theta = line.cov.diagonal() ** 0.5
    print(
        f"t {line.t - sim.beams[0].t:5.1f} s: rho {line.rho_m:6.3f} ± {s_rho:.3f} m, "
        f"theta {math.degrees(line.theta_rad):7.2f} ± {math.degrees(s_theta):.2f} deg, "
        f"{line.votes} votes"
    )
