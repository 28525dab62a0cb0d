"""What flight firmware gets: the C header, the C runtime, and, apart, the host tools
that build and check them.

What ships (its data and the C text):

- :mod:`.dense`: a table as the runtime holds it (float32, the mask, the firmware record).
- :mod:`.runtime`: the Python reference of the C lookup (``c/gainsched_runtime.c``).
- :mod:`.compact`: the compact form (Fourier series in the azimuth per circle) and its
  float32 reference lookup.
- :mod:`.params`: the controller's parameters, from the table alone (its firmware record).
- :mod:`.feedforward`, :mod:`.controller`: the Python references of the feed-forward and
  of the controller's step (``c/gainsched_control.c``).
- :mod:`.sources`: the shipped C (``c/``) and the templates (``templates/``).
- :mod:`.cformat`: C literals and initializers (exact hexadecimal float32).
- :mod:`.header`: ``<name>_gains.h`` of a table; :mod:`.control_header`:
  ``<name>_control.h`` of its controller's parameters.
- :mod:`.cfiles`: the C outputs as files, in memory and written (the runtime copied).

The host tools, :mod:`.host` (compilers, host builds and their ctypes bindings, SIL, PIL,
MISRA, the interpolation check): above what ships, which never imports them.

- :mod:`.outputs`: the output set of a build, checked in memory (a compact table
  certified by :mod:`.host.check`), published at once.
"""
