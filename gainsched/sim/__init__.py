"""Closed-loop flights in simulation.

- :mod:`.loop`: the simulator's flat namespace (scenarios, schedulers, ``simulate``,
  metrics, logs), re-exported from one private module per concept: ``_scenario``,
  ``_plant``, ``_estimator``, ``_result``, ``_loop``, ``_metrics``, ``_schedulers``,
  ``_logout``.
- :mod:`.fastplant`: the compiled rigid-link plant.
- :mod:`.campaign`: simulated test campaigns on plants with a hidden effect.
- :mod:`.paper`: the paper's experiments as a report (``gainsched paper``).
- :mod:`.oldnew`: the standard flights flown with an old and a new table on one plant
  (``gainsched improve``'s before/after).
"""
