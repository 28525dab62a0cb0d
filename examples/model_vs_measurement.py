"""The model-versus-measurement loop from Python (docs/model-vs-measurement.md).

Compare the paper model with the example flights, ask which physical effect is
missing, add it with its fitted parameters, compare again, and repeat until no
candidate explains what is left; then see what the better model changes in the
gains of one circle. Run from the repository root:

    python examples/model_vs_measurement.py [OUT_DIR]

OUT_DIR (default ``mvm-report``) receives each round's reports (Markdown, JSON,
PNG) and the improved config, ``improved.toml``.
"""

import sys
from pathlib import Path

import numpy as np

import gainsched as gs

out = Path(sys.argv[1] if len(sys.argv) > 1 else "mvm-report")
logs = sorted(Path("examples/flights").glob("*.csv"))
paper = config = gs.load_config("configs/paper.toml")
comparison = gs.compare(config, logs)
for round_ in range(1, 4):  # each round adds the effects diagnose accepts
    print(f"round {round_}: {config.name}, normalised RMS {comparison.normalized_rms():.2f}")
    diagnosis = gs.diagnose(config, logs, comparison=comparison)
    gs.write_diagnose(diagnosis, out / f"round{round_}")
    print(f"  {diagnosis.verdict}")
    if diagnosis.accepted is None:
        break
    text = gs.apply_candidate(config, diagnosis.accepted, name=f"{paper.name}_{round_}")
    improved = gs.config_from_text(text, str(out / "improved.toml"))
    after = gs.compare(improved, logs)
    for axis, s in comparison.stats.items():
        print(f"  {axis:10s} RMS {s.rms:10.4g} -> {after.stats[axis].rms:10.4g} {s.unit}")
    config, comparison = improved, after
(out / "improved.toml").write_text(config.text)
gs.write_compare(comparison, out / "final")

# what the better model changes in one circle's LQR: 9 m/s at 20 deg tilt
for cfg in (paper, config):
    sol = gs.solve_circle(cfg, 9.0, np.deg2rad([20.0]))
    print(f"{cfg.name:8s} at 9 m/s, 20 deg: {sol.K.shape[-1]} states, max |K| "
          f"{np.abs(sol.K).max():.2f}, closed-loop spectral radius {sol.spectral_radius[0]:.4f}")
print(f"rebuild the tables: gainsched build {out / 'improved.toml'}")
