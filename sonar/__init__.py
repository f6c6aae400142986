"""The sensor: MSIS beam and head model, beam segmentation, the rolling scan store."""

from sonarslam.sonar.beam import Mounting, SonarBeam, SonarHead

__all__ = ["Mounting", "SonarBeam", "SonarHead"]
