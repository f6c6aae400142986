"""The ``sonarslam`` command: one module per command (parse, call one library function, print);
:mod:`sonarslam.slam.cli.main` builds the parser and turns known errors into one line."""
