"""Closed-loop flights in simulation.

- :mod:`.loop`: scenarios, plants, estimator, the control loop, metrics, logs.
- :mod:`.fastplant`: the compiled rigid-link plant.
- :mod:`.campaign`: simulated test campaigns on plants with a hidden effect.
- :mod:`.paper`: the paper's experiments as a report (``gainsched paper``).
"""
