"""The host tools of the firmware: what builds, runs and checks the shipped C here, on
the development machine, and never goes to the autopilot.

- :mod:`.compiler`: which C compiler and with which flags (the strict warning set,
  the Cortex-M4F target), a compile that fails with the compiler's output.
- :mod:`.size`: the flash footprint (the table's bytes, the runtime's code bytes).
- :mod:`.lookup`: the lookup compiled for the host (:func:`~.lookup.build_host`) and
  called through ctypes (:class:`~.lookup.CRuntime`).
- :mod:`.sil`: software in the loop, the C controller through ctypes.
- :mod:`.pil`: processor in the loop, the runtime and the controller cross-compiled and
  run on an emulated Cortex-M4F.
- :mod:`.misra`: MISRA C:2012 of the hand-written C (cppcheck, ``misra_deviations.txt``).
- :mod:`.check`: the interpolation check of a built table (``gainsched check``; the
  compact form's certificate) against LQR solved again here.

The shipped modules of :mod:`gainsched.firmware` never import these (the import
contract in pyproject.toml); the output set of a build (:mod:`gainsched.firmware.outputs`)
sits above them, as it certifies a compact table with :mod:`.check`.
"""
