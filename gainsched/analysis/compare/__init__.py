"""Model versus measurement: the residual of the model on flight logs (a package being
split into one private module per concept; this namespace is the API)."""

from ._measured import (
    AT_NOISE_FLOOR,
    AXES,
    BIN_VARIABLES,
    MOTOR_ORDER_FACTOR,
    UNITS,
    AxisStats,
    Comparison,
    Measured,
    Residual,
    axis_stats,
    centred_commands,
    check_motor_order,
    compare,
    load_segments,
    measure,
    motor_order_fits,
    noise_floor,
    predict,
    residual_axes,
    residuals,
    tracking_summary,
    where_it_fails,
    window_samples,
)
from ._measured import (
    has_channel as has_channel,  # not public: analysis.diagnose uses it
)

__all__ = [
    "centred_commands",
    "AXES",
    "UNITS",
    "BIN_VARIABLES",
    "Measured",
    "Residual",
    "AxisStats",
    "Comparison",
    "load_segments",
    "measure",
    "predict",
    "residuals",
    "residual_axes",
    "axis_stats",
    "where_it_fails",
    "compare",
    "tracking_summary",
    "window_samples",
    "noise_floor",
    "AT_NOISE_FLOOR",
    "MOTOR_ORDER_FACTOR",
    "motor_order_fits",
    "check_motor_order",
]
