"""``physval sim2sim MODEL_FILE``: one robot model in every engine, judged tier by tier.

In phases, every input checked before any work:

1. **Read the request**: the model file (a path or ``pkg:PACKAGE/path``; URDF ``.urdf`` or
   MJCF ``.xml``), the engines (default ``model_engines``: every installed engine with joints,
   the native loaders first) and the ``--package-path`` flags. Bad input is one line, exit 2.
2. **Write the scene** (``scene_text``): the model on a fixed base at its default
   configuration (every movable joint at 0, or at the middle of its limits where 0 is outside
   them), each joint given ``SWING_VELOCITY``, a passive swing under gravity for
   ``SWING_DURATION``, collisions off, with ``SIM2SIM_CHECKS``. It is loaded as ``physval
   check`` loads it: a model the reader refuses is one line naming the model file.
3. **Run it** through ``physval run``'s own machinery (``run.run_main``): the same run folder,
   ``--out`` rules, exit codes; the scene goes into the run folder as ``scene.yaml``
   (``SCENE_FILE``), so ``physval run DIR/scene.yaml`` runs it again.
4. **The verdict** (``verdicts``): per engine pair, the first tier (``TIERS``) where one of
   the two engines' rows failed, with that row's message (it names the link or field); or
   ``agree on every tier``.
"""

from __future__ import annotations

import itertools
import json
import re
import sys
import tempfile
from pathlib import Path

from validation.contract import BAD_STATUSES, EXIT_BAD_INPUT, RESULTS_FILE, SCENE_FILE
from validation.engine_api import MODEL_LOADER_OPTION, declarations
from validation.jobs.plan import BadInputError, use_package_paths
from validation.scenario import Scenario, ScenarioError, load_scenario
from validation.scenario.compiled import compile_scene
from validation.scenario.definability import scene_traits, why_undefined
from validation.scenario.engine_spec import (
    EngineSpecError,
    not_installed,
    parse_installed_spec,
    split_engine_list,
)
from validation.scenario.problems import printable
from validation.scenario.schema import METRIC_NAMES
from validation.scenario.urdf import PACKAGE_PREFIX, model_path, read_urdf

try:  # the tier order (issue 36's plan, item 1: validation/measure/tiers.py)
    from validation.measure.tiers import TIERS
except ImportError:  # until the tiers land on main: the same order (MODELS.md)
    TIERS = (
        ("model_fields",),
        ("fk_error",),
        ("mass_matrix_error", "bias_force_error"),
        ("joint_divergence", "agreement_time", "energy_drift", "joint_violation"),
    )

MODEL_FORMATS = {".urdf": "URDF", ".xml": "MJCF"}
"""Model file suffix -> the format read from it."""

DEFAULT_OUT = Path("reports") / "sim2sim"
"""Where ``physval sim2sim`` publishes without ``--out``."""

SWING_DURATION = 1.0
"""s: the passive swing. Long enough for the Kuka, started upright, to fall through half a
radian, so the trajectory tier sees the engines part; short enough that the five engines run
it in seconds."""

SWING_DT = 1e-3
"""s: the step (the library's joint scenes' step)."""

SWING_VELOCITY = 0.5
"""rad/s (m/s on a slider): every movable joint's velocity at t = 0. A model's zero pose is
often an equilibrium (the Kuka stands upright, a pendulum hangs), where nothing would move:
the push makes the swing exercise every joint's dynamics; 0.5 rad/s moves a joint by about
half a radian over ``SWING_DURATION``."""

SIM2SIM_CHECKS: dict[str, float | dict[str, float]] = {
    # relative: a field as written in a model file has 4 to 7 significant digits, read the
    # same way by every loader (1e-16); a loader that drops a frame or a field differs by
    # more than 1e-3; float32 engines (Rapier) round each field at 6e-8
    "model_fields": 1e-6,
    # m: the same chain of transforms composed in double precision (round-off ~1e-15 m on a
    # metre-sized arm); Rapier's float32 poses round at ~1e-7 m
    "fk_error": 1e-6,
    # relative to the largest entry: the composite-rigid-body and Newton-Euler sums of an
    # engine against the reference side's, round-off in float64; Rapier's float32 mass
    # matrix differs by 1.6e-6 (tests/test_models.py's ENGINES note)
    "mass_matrix_error": 1e-5,
    "bias_force_error": 1e-5,
    # rad or m: two first-order schemes at dt = 1 ms part by O(dt) per unit time; over the
    # 1 s swing the library's joint scenes part by up to a few 1e-2 rad
    "joint_divergence": 5e-2,
    # relative to the energy scale: a damped model loses energy to its joints' damping (the
    # Kuka: 0.5 N·m·s/rad each); first-order schemes lose a further ~3e-3 per 0.2 s at dt =
    # 1 ms (tests/test_models.py's ENERGY_RATE)
    "energy_drift": 5e-2,
    # m: reduced-coordinate engines hold joints to round-off; maximal-coordinate ones (mini,
    # Rapier) drift by v²/L · dt² per step over β (scenarios/joints/chain_falling.yaml's 6e-4)
    "joint_violation": 1e-3,
}
"""The sim2sim scene's ``checks:``, one per tier metric. ``agreement_time`` is read, not
judged (it is the time ``joint_divergence``'s band holds, so it fails with it). A metric the
scene format does not name yet (``METRIC_NAMES``) is left out of the written scene."""

AGREEING = "agree on every tier"
VERDICT_TITLE = "sim2sim: the first tier where each engine pair disagrees"

NOT_AGREEING_OUTCOMES = (*BAD_STATUSES, "unsupported", "not_installed")
"""A row with one of these outcomes (results.csv's ``outcome``) is a disagreement at its tier:
a failed check, or an engine that could not run the model."""


def model_engines() -> list[str]:
    """Every installed engine with joints (the engines able to load a model), those with a
    native loader (``MODEL_LOADER_OPTION``) first, each group in the declarations' order."""
    able = [
        declaration
        for declaration in declarations().values()
        if "joints" in declaration.capabilities.features and not not_installed(declaration.name)
    ]
    native = [d.name for d in able if d.option(MODEL_LOADER_OPTION.name)]
    return native + [d.name for d in able if d.name not in native]


def engine_list(engines: list[str] | None) -> list[str]:
    """``--engines`` (each a spec or a comma list of specs) checked, or ``model_engines``;
    ``BadInputError`` naming the first unknown engine or setting."""
    if not engines:
        return model_engines()
    texts = [text for given in engines for text in split_engine_list(given)]
    for text in texts:
        try:
            parse_installed_spec(text)
        except EngineSpecError as error:
            raise BadInputError(f"--engines: {error}") from None
    if len(set(texts)) != len(texts):
        raise BadInputError(f"--engines: an engine is listed twice ({', '.join(texts)})")
    return texts


def model_file(text: str) -> tuple[str, Path]:
    """MODEL_FILE as the scene names it (``pkg:...`` as given, a path made absolute) and the
    file it is; ``BadInputError`` when it is missing or neither URDF nor MJCF."""
    try:
        path = model_path(text, Path.cwd() / "scene")
    except ValueError as error:
        raise BadInputError(f"{printable(text)}: {error}") from None
    if path.suffix.lower() not in MODEL_FORMATS:
        raise BadInputError(
            f"{printable(text)}: expected a URDF (.urdf) or MJCF (.xml) model file; got "
            f"{printable(path.name)!r}"
        )
    if not path.is_file():
        raise BadInputError(f"{printable(text)}: no such file")
    named = text if text.startswith(PACKAGE_PREFIX) else str(path.resolve())
    return named, path


def default_configuration(path: Path) -> dict[str, float]:
    """File joint name -> its position at t = 0: the middle of its limits where 0 is outside
    them (others 0, not listed). A URDF's limits are read here; an MJCF model starts at its
    ``qpos0`` (0). ``ValueError`` when the URDF cannot be read."""
    if MODEL_FORMATS[path.suffix.lower()] != "URDF":
        return {}
    robot = read_urdf(path)
    return {
        joint.name: (joint.limits[0] + joint.limits[1]) / 2
        for joint in robot.joints
        if joint.limits is not None and not joint.limits[0] <= 0.0 <= joint.limits[1]
    }


def model_name(path: Path) -> str:
    """The model's name in the scene: the file's stem, other characters than a scene name's
    (letters, digits, ``_ . -``) as ``_``."""
    return re.sub(r"[^A-Za-z0-9_.\-]", "_", path.stem) or "model"


def _mapping(entries: dict, indent: str) -> list[str]:
    """``entries`` as YAML block lines at ``indent`` (``{}`` when empty); keys and values
    written as JSON, which YAML reads."""
    if not entries:
        return [" {}"]
    return ["", *(f"{indent}{json.dumps(k)}: {json.dumps(v)}" for k, v in entries.items())]


def scene_text(
    named: str,
    name: str,
    engines: list[str],
    positions: dict[str, float],
    velocities: dict[str, float],
    checks: dict[str, float | dict[str, float]],
    duration: float,
    dt: float,
) -> str:
    """The sim2sim scene of one model as YAML."""
    positions = {f"{name}/{joint}": q for joint, q in positions.items()}
    velocities = {f"{name}/{joint}": v for joint, v in velocities.items()}
    lines = [
        f"# Written by physval sim2sim for {named}: physval run FILE runs it again.",
        f"name: {json.dumps('sim2sim-' + name)}",
        "description: >-",
        f"  {name} on a fixed base at its default configuration, every joint pushed at",
        f"  {SWING_VELOCITY:g} rad/s (m/s), swinging under gravity: the model tiers and the",
        "  trajectory tier compared across engines.",
        f"dt: {dt!r}",
        f"duration: {duration!r}",
        f"engines: {json.dumps(engines)}",
        "models:",
        f"  - name: {json.dumps(name)}",
        f"    file: {json.dumps(named)}",
        "    fixed_base: true",
        "    collisions: false",
        "    joint_positions:" + "\n".join(_mapping(positions, "      ")),
        "    joint_velocities:" + "\n".join(_mapping(velocities, "      ")),
        "checks:" + "\n".join(_mapping(checks, "  ")),
    ]
    return "\n".join(lines) + "\n"


def _loaded(scene: Path, model: str) -> Scenario:
    """The scene as ``physval check`` loads it; ``BadInputError`` naming the model file with
    the reader's first problem."""
    try:
        return load_scenario(scene)
    except ScenarioError as error:
        first = next((p for p in error.problems if p.path.startswith("models")), None)
        first = first or error.problems[0]
        raise BadInputError(
            f"{printable(model)}: cannot be read ({first.path}: {first.message})"
        ) from None


def scene_checks(scenario: Scenario) -> dict[str, float | dict[str, float]]:
    """``SIM2SIM_CHECKS`` the scene format names (``METRIC_NAMES``) and the scene defines
    (``definability``: a damped model has no ``energy_drift``)."""
    traits = scene_traits(compile_scene(scenario))
    return {
        metric: value
        for metric, value in SIM2SIM_CHECKS.items()
        if metric in METRIC_NAMES and why_undefined(metric, traits) is None
    }


def write_scene(folder: Path, model: str, engines: list[str], duration: float, dt: float) -> Path:
    """The sim2sim scene of ``model`` written to ``folder`` (phase 2): loaded once still
    without its push and checks, to find the model's movable joints, once with its push, to
    find the checks it defines; ``BadInputError`` when the model cannot be read."""
    named, path = model_file(model)
    try:
        positions = default_configuration(path)
    except ValueError as error:
        raise BadInputError(f"{printable(model)}: cannot be read ({error})") from None
    name = model_name(path)
    scene = folder / f"{name}.yaml"

    def written(velocities: dict[str, float], checks: dict) -> Scenario:
        scene.write_text(
            scene_text(named, name, engines, positions, velocities, checks, duration, dt)
        )
        return _loaded(scene, model)

    prefix = name + "/"
    movable = [j.name[len(prefix) :] for j in written({}, {}).joints if j.type != "fixed"]
    velocities = dict.fromkeys(movable, SWING_VELOCITY)
    written(velocities, scene_checks(written(velocities, {})))
    return scene


def _failed(rows, engine: str, metric: str):
    """The row of ``engine``'s ``metric`` when it disagrees (``NOT_AGREEING_OUTCOMES``), else
    None."""
    found = rows[(rows["engine"] == engine) & (rows["metric"] == metric)]
    bad = found[found["outcome"].isin(NOT_AGREEING_OUTCOMES)]
    return None if bad.empty else bad.iloc[0]


def pair_verdict(rows, a: str, b: str) -> str:
    """``a`` and ``b``'s first tier where one of them disagrees, with the row's message."""
    for number, tier in enumerate(TIERS, start=1):
        for metric in tier:
            for engine in (a, b):
                row = _failed(rows, engine, metric)
                if row is not None:
                    why = row["message"] or f"{row['outcome']}: {metric} {row['value_text']}"
                    return f"tier {number} ({metric}): {engine}: {why}"
    return AGREEING


def verdicts(results: Path) -> list[str]:
    """One line per engine pair of the run folder's results: ``a vs b: <pair_verdict>``."""
    from validation.report.read import read_results

    rows = read_results(results)
    engines = list(dict.fromkeys(rows["engine"]))
    return [
        f"{a} vs {b}: {pair_verdict(rows, a, b)}" for a, b in itertools.combinations(engines, 2)
    ]


def sim2sim_main(
    model: str,
    engines: list[str] | None,
    out: Path | None,
    package_paths: list[str] | None,
    duration: float | None,
    dt: float | None,
    argv: list[str],
    jobs: int = 1,
    job_timeout: float | None = None,
) -> int:
    """The whole command (module docstring); the exit code, as ``physval run``'s."""
    from validation.jobs.run import run_main

    out = DEFAULT_OUT if out is None else out
    with tempfile.TemporaryDirectory(prefix="physval-sim2sim-") as folder:
        try:
            use_package_paths(package_paths)
            specs = engine_list(engines)
            scene = write_scene(
                Path(folder), model, specs, duration or SWING_DURATION, dt or SWING_DT
            )
        except BadInputError as error:
            print(error, file=sys.stderr)
            return EXIT_BAD_INPUT
        code = run_main(
            [scene],
            None,
            out,
            None,
            None,
            argv,
            jobs,
            baseline="none",
            history="none",
            job_timeout=job_timeout,
            extra_files={SCENE_FILE: scene.read_text()},
        )
    if code == EXIT_BAD_INPUT or not (out / RESULTS_FILE).is_file():
        return code
    print(VERDICT_TITLE)
    print("\n".join(verdicts(out / RESULTS_FILE)))
    return code
