"""The ``sonarslam`` command: :mod:`sonarslam.slam.cli.parsers` says what each command accepts
(argparse alone, so that help answers at once), one module per command runs it (call one library
function, print), and :mod:`sonarslam.slam.cli.main` builds the parser, imports the one command
that runs and turns known errors into one line."""
