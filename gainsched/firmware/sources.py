"""The C text shipped in the package: the hand-written runtime and controller (``c/``)
and the templates the generated files are filled from (``templates/``).

What is copied as is (:data:`RUNTIME_FILES`, :data:`CONTROL_FILES`), read by name
(:func:`resource`), and what is filled in (:func:`render`: ``${key}`` placeholders,
which C never uses). The generated headers say which runtime they were made for
(:data:`RUNTIME_VERSION`).
"""

from __future__ import annotations

import string
from importlib import resources

__all__ = ["RUNTIME_FILES", "CONTROL_FILES", "RUNTIME_VERSION", "resource", "render"]

#: the lookup (its header and source, which also implements the trigonometry) and the
#: trigonometry's header (docs/runtime.md, "Files")
RUNTIME_FILES = ("gainsched_runtime.h", "gainsched_runtime.c", "gainsched_trig.h")
#: the controller (pose and gyro to thrusts) shipped beside the runtime
CONTROL_FILES = ("gainsched_control.h", "gainsched_control.c")
#: the runtime's interface version, checked by the generated header
RUNTIME_VERSION = 5


def resource(*parts) -> str:
    """The text of a shipped file: ``resource("c", "gainsched_runtime.c")``,
    ``resource("templates", "pil.ld")``."""
    return resources.files("gainsched.firmware").joinpath(*parts).read_text()


def render(template: str, **values) -> str:
    """Fill ``templates/<template>`` (``${key}`` placeholders; C never uses ``$``)."""
    return string.Template(resource("templates", template)).substitute(values)
