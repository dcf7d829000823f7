# %% [markdown]
# # physval from Python
#
# A notebook in cell style (`# %%`): Jupyter (with jupytext), VS Code and PyCharm run it cell
# by cell; `python docs/examples/python_api.py` runs it whole (tests/test_python_api.py does).
# It checks a scene of its own, loads it, runs it in two engines and reads the rows.

# %%
import tempfile
from pathlib import Path

import physval

work = Path(tempfile.mkdtemp(prefix="physval-notebook-"))
scene = work / "drop.yaml"
scene.write_text(
    """\
description: A ball dropped in uniform gravity, touching nothing.
dt: 1.0e-3
duration: 1.0
engines: [mini, mujoco]
bodies:
  - {name: ball, shape: {type: sphere, radius: 0.1}, mass: 1.0, position: [0, 0, 5.0]}
expect:
  # z(1) = 5 - 9.81/2
  - {kind: position_at, body: ball, time: 1.0, value: [0.0, 0.0, 0.095]}
checks:
  # semi-implicit Euler lands g·t·dt/2 = 4.9 mm low at t = 1 s (docs/engines.md 1.6)
  position_at.ball: 6.0e-3
"""
)

# %% [markdown]
# `check` returns every problem (an empty list: the file is valid); `load_scene` the
# validated scene. Both raise `physval.InputError` for what they cannot read.

# %%
assert physval.check(scene) == []
drop = physval.load_scene(scene)
print(drop.name, drop.dt, [body.name for body in drop.bodies])

# %% [markdown]
# `run` returns the rows as a pandas DataFrame (results.csv's columns). Without `out`
# nothing stays on disk; with it, the run folder (report.html too) is published there.

# %%
results = physval.run(scene, engines="mini, mujoco", out=work / "run")
print(results.passed, results.folder)
checked = results.rows[results.rows["tolerance"].notna()]
print(checked[["engine", "metric", "error", "tolerance", "outcome"]].to_string(index=False))

# %% [markdown]
# A typo is refused before any work, with the line `physval` would print.

# %%
try:
    physval.run(scene, engines="mujoko")
except physval.InputError as error:
    print(error.problems)
