"""A gain schedule plotted in 15 lines: one gain over azimuth, a curve per speed.
Run from the repository root: python examples/plot_gains.py [TABLE] [OUT.png]"""
import sys

import matplotlib.pyplot as plt
import numpy as np

import gainsched as gs

table = gs.load_table(sys.argv[1] if len(sys.argv) > 1 else "tables/paper.h5")
lookup, xi = gs.Interpolator(table), np.linspace(0.0, 2 * np.pi, 361)
motor, state = 0, table.state_names.index("delta")  # thrust T1 on the polar error
for speed, xi_dot in list(zip(table.speed, table.xi_dot, strict=True))[::4]:
    gains = lookup(xi, xi_dot, np.deg2rad(20.0))  # K: (361, 4, n), N per state unit
    K = np.where(gains.status == 0, gains.K[:, motor, state], np.nan)  # none: infeasible
    plt.plot(np.rad2deg(xi), K, label=f"{speed:g} m/s")
plt.xlabel("azimuth xi, deg"), plt.ylabel("K[T1, delta], N/rad"), plt.legend()
plt.title(f"{table.name}: tilt 20 deg")
plt.savefig(sys.argv[2] if len(sys.argv) > 2 else "gains.png")
