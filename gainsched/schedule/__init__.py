"""The gain schedule, from a config to a table: the compiler's flow.

:mod:`.path` (azimuth profiles) -> :mod:`.closedform` / :mod:`.trim` -> :mod:`.nominal`
(nominal and feasibility) -> :mod:`.linearize` -> :mod:`.lqr` (periodic LQR) ->
:mod:`.grid` (every circle of the grid, locally or with :mod:`.distributed`) ->
:mod:`.tables` (the HDF5 table) -> :mod:`.envelope` (its flight envelope as a plot) and
:mod:`.viewer` (every gain, the nominal and the closed loop as plots); :mod:`.sweep` builds
one table per vehicle variant.
"""
