"""Motion model, pose sources, data association, EKF-SLAM, factor graph, pipeline, evaluation, CLI."""
