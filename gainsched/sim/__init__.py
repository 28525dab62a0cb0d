"""Closed-loop flights in simulation.

- :mod:`.loop`: scenarios, plants, estimator, the control loop, metrics, logs.
- :mod:`.fastplant`: the compiled rigid-link plant.
- :mod:`.campaign`: simulated test campaigns on plants with a hidden effect.
- :mod:`.paper`: the paper's experiments as a report (``gainsched paper``).
- :mod:`.oldnew`: the standard flights flown with an old and a new table on one plant
  (``gainsched improve``'s before/after).
"""
