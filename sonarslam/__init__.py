"""sonarslam: line features with honest uncertainty from a mechanically scanned imaging sonar,
and SLAM with them.

The layers are subpackages, in the order data flows through them: :mod:`sonarslam.datasets`
(readers and the simulator), :mod:`sonarslam.sonar` (the sensor), :mod:`sonarslam.features`
(the line front end), :mod:`sonarslam.slam` (back ends, evaluation, the command line).
"""
