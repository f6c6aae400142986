"""The GTSAM iSAM2 back end: factors, the graph, its odometry and pose source, graph files."""
