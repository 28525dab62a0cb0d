"""What flight firmware gets: the C header, the C runtime and their checks.

- :mod:`.dense`: a table as the runtime holds it (float32, the mask, the firmware record).
- :mod:`.runtime`: the Python reference of the C lookup (``c/gainsched_runtime.c``).
- :mod:`.compact`: the compact form (Fourier series in the azimuth per circle) and its
  float32 reference lookup.
- :mod:`.params`: the controller's parameters, from the table alone (its firmware record).
- :mod:`.codegen`: the C header from a table (``templates/``), host builds for tests.
- :mod:`.outputs`: the output set of a build, checked in memory, published at once.
- :mod:`.check`: the interpolation check of a built table (``gainsched check``).
"""
