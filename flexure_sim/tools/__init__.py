"""
Command-line tools built on the engine and the recording layer.

- ``run``: recorded runs (info, analyse, plot, export);
- ``design``: the designer's commands (modes, frf, linearize, sensitivity, sweep, fit);
- ``bench``: measurements (flexure-sim bench, the node's timing harness, closed loop).
"""
