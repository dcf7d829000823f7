"""``physval sim2sim MODEL_FILE``: one robot model in every engine, judged tier by tier.

In phases, every input checked before any work:

1. **Read the request**: the model file (a path or ``pkg:PACKAGE/path``; URDF ``.urdf`` or
   MJCF ``.xml``), the engines (default ``model_engines``: every installed engine with joints,
   the native loaders first) and the ``--package-path`` flags. Bad input is one line, exit 2.
2. **Write the scene** (``write_scene``, ``Swing``): the model on a fixed base turned so
   that it hangs below it (``hanging``), at its default configuration (every movable joint
   at 0, or at the middle of its limits where 0 is outside them), each movable joint given
   ``SWING_VELOCITY``, a passive swing under gravity for ``SWING_DURATION``, collisions off,
   with ``SIM2SIM_CHECKS``. It is loaded as ``physval check`` loads it: a model the reader
   refuses, or one without a movable joint, is one line naming the model file.
3. **Run it** through ``physval run``'s own machinery (``run.run_main``): the same run folder,
   ``--out`` rules, exit codes; the scene goes into the run folder as ``scene.yaml``
   (``SCENE_FILE``), so ``physval run DIR/scene.yaml`` runs it again.
4. **The verdict** (``verdicts``): per engine pair, the first tier (``TIERS``) where a row
   of one of the two engines is beyond its tolerance, with that row's message (it names the
   link or field); else a run that did not end ``ok``, with its status; else ``agree on every
   tier``.
"""

from __future__ import annotations

import itertools
import json
import re
import sys
import tempfile
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from validation.contract import EXIT_BAD_INPUT, RESULTS_FILE, SCENE_FILE
from validation.engine_api import MODEL_LOADER_OPTION, declarations
from validation.jobs.plan import BadInputError, use_package_paths
from validation.measure.definitions import TIERS
from validation.scenario import Scenario, ScenarioError, load_scenario
from validation.scenario.compiled import compile_scene
from validation.scenario.definability import scene_traits, why_undefined
from validation.scenario.engine_spec import (
    EngineSpecError,
    not_installed,
    parse_engine_spec,
    parse_installed_spec,
    split_engine_list,
)
from validation.scenario.problems import printable
from validation.scenario.schema import METRIC_NAMES
from validation.scenario.urdf import PACKAGE_PREFIX, READERS, model_path

DEFAULT_OUT = Path("reports") / "sim2sim"
"""Where ``physval sim2sim`` publishes without ``--out``."""

SWING_DURATION = 1.0
"""s: the passive swing: about one period of the Kuka hanging from its base, short enough
that five engines run it in seconds."""

SWING_DT = 1e-3
"""s: the step (the library's joint scenes' step)."""

SWING_VELOCITY = 0.5
"""rad/s (m/s on a slider): every movable joint's velocity at t = 0. Hung below its base
(``hanging``), a model at its default configuration is near an equilibrium, where nothing
would move: the push swings every joint, by some 0.1 rad."""

HANGING_MIN_OFFSET = 1e-9
"""m: a model whose centre of mass is closer than this to its base is left as the file
places it (there is no direction to hang it along)."""

SIM2SIM_CHECKS: dict[str, float | dict[str, float]] = {
    # relative: every loader reads the file's digits alike, to round-off (measured on the
    # hanging Kuka and a two-link arm: 3e-15 and less in MuJoCo, PyBullet, Drake and mini); a
    # loader that drops a frame or a field differs by 1e-3 or more. Rapier holds its fields
    # in float32: 2.5e-7 and 5.5e-7 on the Kuka
    "model_fields": {"default": 1e-6, "rapier": 1e-5},
    # m: link poses over the probed states: 4e-16 to 1e-15 m where a centre is worst; a
    # rotation angle read from a float64 rotation resolves ~1.5e-8 rad (sqrt of the unit
    # round-off), 1e-8 to 5e-8 m at the Kuka's reach (MuJoCo, Drake); Rapier float32 8.5e-8 m
    "fk_error": 1e-6,
    # relative to the largest entry: the engines' M(q) against the composite-rigid-body sum,
    # round-off in float64 (1.8e-15 and less on the Kuka); Rapier float32 7.2e-7
    "mass_matrix_error": {"default": 1e-9, "rapier": 1e-5},
    # relative: an engine's bias forces (its model_probe) against Newton-Euler, round-off
    # (5.4e-13 on the hanging Kuka, whose |b| is small at rest). The engines without a
    # model_probe (mini, Rapier) are judged by a one-step finite difference, first order in
    # dt (its row has a band): mini 5.0e-4 on the Kuka at dt = 1 ms where |b| is 38 N·m, so
    # 5e-3. Where the probed state is near an equilibrium (|b| of 1e-4 and less: the arm and
    # the cart-pole hanging at rest) the relative difference is larger (1e-2): not widened here
    "bias_force_error": {"default": 1e-9, "mini": 5e-3, "rapier": 5e-3},
    # rad or m, from the scene's first engine: two first-order schemes part by O(dt). Over
    # the 1 s swing at 1 ms, from MuJoCo: the hanging Kuka 6.0e-4 rad (mini), 5.5e-4
    # (PyBullet), 1.3e-4 (Rapier), 7e-13 (Drake); the two-link arm, the cart-pole and the
    # MJCF double pendulum 1e-5 and less; a loader's real difference (PyBullet's reading of
    # the pendulum's damping) parts by 2.3e-2
    "joint_divergence": 2e-3,
    # s, the time lost (the swing's duration less the time within joint_divergence's band):
    # none, so it fails exactly when joint_divergence does, and says when the pair parted
    "agreement_time": 0.0,
    # relative to the energy scale: first-order schemes at dt = 1 ms, the undamped two-link
    # arm's swing 3.3e-4 (MuJoCo, PyBullet, Drake) and 3.4e-4 (mini), the cart-pole's 1.1e-4;
    # 5e-3 holds a model with faster links tenfold. A damped model (the Kuka) has no
    # energy_drift row
    "energy_drift": 5e-3,
    # m: reduced-coordinate engines hold joints to round-off (1e-16); maximal-coordinate ones
    # drift by v²/L · dt² per step over β: mini 2.7e-7 and Rapier 2.5e-7 on the Kuka's swing
    "joint_violation": 1e-4,
}
"""The sim2sim scene's ``checks:``, one per tier metric: a number, or ``{default: x, <engine
name>: y}`` (the entry of an engine applies to each of its specs in the scene). A metric the
scene format does not name (``METRIC_NAMES``) or the scene cannot define (``definability``) is
left out of the written scene."""

AGREEING = "agree on every tier"
VERDICT_TITLE = "sim2sim: the first tier where each engine pair disagrees"

SCENE_FLAGS = {"dt": "--dt", "duration": "--duration", "engines": "--engines"}
"""A field of the written scene -> the flag that sets it (a problem there is the flag's)."""

REASON_SEPARATOR = "; "
"""Between the reasons of one status message (``_first_reason``)."""

RUN_STATUS_METRIC = "status"
"""The row an engine's run writes when it did not end ``ok`` (``measure.comparator``): its
status (unstable, error, unsupported, ...) and why."""


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
    if path.suffix.lower() not in READERS:
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
    them (others 0, not listed: a swing pushed from a limit would start against its stop).
    ``ValueError`` when the file cannot be read."""
    robot = READERS[path.suffix.lower()][1](path)
    return {
        joint.name: (joint.limits[0] + joint.limits[1]) / 2
        for joint in robot.joints
        if joint.limits is not None and not joint.limits[0] <= 0.0 <= joint.limits[1]
    }


def model_name(path: Path) -> str:
    """The model's name in the scene: the file's stem, other characters than a scene name's
    (letters, digits, ``_ . -``) as ``_``."""
    return re.sub(r"[^A-Za-z0-9_.\-]", "_", path.stem) or "model"


def hanging(scenario: Scenario) -> tuple[float, float, float, float]:
    """The base orientation (w, x, y, z) that hangs the model's centre of mass at t = 0
    straight below its base, along gravity; the identity when the centre of mass is on the
    base (within ``HANGING_MIN_OFFSET``: nothing to hang)."""
    masses = np.array([body.mass for body in scenario.bodies])
    centre = masses @ np.array([body.position for body in scenario.bodies]) / masses.sum()
    if np.linalg.norm(centre) < HANGING_MIN_OFFSET:
        return (1.0, 0.0, 0.0, 0.0)
    down = np.array(scenario.gravity) / np.linalg.norm(scenario.gravity)
    turn, _ = Rotation.align_vectors([down], [centre])
    x, y, z, w = turn.as_quat()
    return (float(w), float(x), float(y), float(z))


def _mapping(entries: dict, indent: str) -> str:
    """``entries`` as YAML block lines at ``indent`` (`` {}`` when empty); keys and values
    written as JSON, which YAML reads."""
    if not entries:
        return " {}"
    return "".join(f"\n{indent}{json.dumps(k)}: {json.dumps(v)}" for k, v in entries.items())


@dataclass(frozen=True)
class Swing:
    """The sim2sim scene of one model (module docstring, phase 2)."""

    named: str
    """The model file as the scene names it."""
    name: str
    engines: list[str]
    duration: float
    dt: float
    positions: dict[str, float] = field(default_factory=dict)
    """File joint name -> rad or m at t = 0 (others 0)."""
    velocities: dict[str, float] = field(default_factory=dict)
    orientation: tuple[float, float, float, float] = (1.0, 0.0, 0.0, 0.0)
    checks: dict[str, float | dict[str, float]] = field(default_factory=dict)

    def text(self) -> str:
        """The scene as YAML."""
        prefixed = {
            key: {f"{self.name}/{joint}": value for joint, value in values.items()}
            for key, values in (
                ("joint_positions", self.positions),
                ("joint_velocities", self.velocities),
            )
        }
        lines = [
            f"# Written by physval sim2sim for {self.named}: physval run FILE runs it again.",
            f"name: {json.dumps('sim2sim-' + self.name)}",
            "description: >-",
            f"  {self.name} on a fixed base turned so that the model hangs below it, at its",
            f"  default configuration, every joint pushed at {SWING_VELOCITY:g} rad/s (m/s),",
            "  swinging under gravity: the model tiers and the trajectory tier across engines.",
            f"dt: {self.dt!r}",
            f"duration: {self.duration!r}",
            f"engines: {json.dumps(self.engines)}",
            "models:",
            f"  - name: {json.dumps(self.name)}",
            f"    file: {json.dumps(self.named)}",
            f"    orientation: {json.dumps(self.orientation)}",
            "    fixed_base: true",
            "    collisions: false",
            *(f"    {key}:{_mapping(values, '      ')}" for key, values in prefixed.items()),
            f"checks:{_mapping(self.checks, '  ')}",
        ]
        return "\n".join(lines) + "\n"


def _loaded(swing: Swing, scene: Path, model: str) -> Scenario:
    """``swing`` written to ``scene`` and loaded as ``physval check`` loads it;
    ``BadInputError`` with its first problem: the model file's, or the flag's that set the
    field (``SCENE_FLAGS``)."""
    scene.write_text(swing.text())
    try:
        return load_scenario(scene)
    except ScenarioError as error:
        first = next((p for p in error.problems if p.path.startswith("models")), None)
        if first is not None:
            raise BadInputError(
                f"{printable(model)}: cannot be read ({first.path}: {first.message})"
            ) from None
        first = error.problems[0]
        flag = SCENE_FLAGS.get(first.path.split(".")[0], first.path)
        raise BadInputError(f"{flag}: {first.message}") from None


def _tolerance(value: float | dict[str, float], engines: list[str]) -> float | dict[str, float]:
    """A ``SIM2SIM_CHECKS`` value for the scene's engine specs: an entry by engine name
    applies to every spec of that engine (``rapier`` to ``rapier(x=1)`` too)."""
    if not isinstance(value, dict):
        return value
    names = {spec: parse_engine_spec(spec).name for spec in engines}
    return {"default": value["default"]} | {
        spec: value[name] for spec, name in names.items() if name in value
    }


def scene_checks(scenario: Scenario) -> dict[str, float | dict[str, float]]:
    """``SIM2SIM_CHECKS`` the scene format names (``METRIC_NAMES``) and the scene defines
    (``definability``: a damped model has no ``energy_drift``; ``agreement_time`` needs
    ``joint_divergence``'s tolerance), each for the scene's engine specs (``_tolerance``)."""
    checks = {
        metric: _tolerance(value, scenario.engines)
        for metric, value in SIM2SIM_CHECKS.items()
        if metric in METRIC_NAMES
    }
    while True:  # a check dropped may undefine another (agreement_time without its band)
        traits = scene_traits(compile_scene(scenario.model_copy(update={"checks": checks})))
        defined = {m: v for m, v in checks.items() if why_undefined(m, traits) is None}
        if defined == checks:
            return checks
        checks = defined


def write_scene(folder: Path, model: str, engines: list[str], duration: float, dt: float) -> Path:
    """The sim2sim scene of ``model`` written to ``folder`` (phase 2): loaded at rest, to
    find the model's movable joints and its centre of mass, then with its push, to find the
    checks it defines; ``BadInputError`` when the model cannot be read."""
    named, path = model_file(model)
    try:
        positions = default_configuration(path)
    except ValueError as error:
        raise BadInputError(f"{printable(model)}: cannot be read ({error})") from None
    swing = Swing(named, model_name(path), engines, duration, dt, positions)
    scene = folder / SCENE_FILE
    at_rest = _loaded(swing, scene, model)
    prefix = swing.name + "/"
    movable = [j.name[len(prefix) :] for j in at_rest.joints if j.type != "fixed"]
    if not movable:
        raise BadInputError(
            f"{printable(model)}: has no movable joint; expected a model with revolute, "
            "continuous or prismatic (hinge or slide) joints to swing"
        )
    swing = replace(
        swing,
        velocities=dict.fromkeys(movable, SWING_VELOCITY),
        orientation=hanging(at_rest),
    )
    swing = replace(swing, checks=scene_checks(_loaded(swing, scene, model)))
    _loaded(swing, scene, model)
    return scene


def _first_reason(message: str) -> str:
    """A status message's first reason (they are ``; ``-separated: the parity gate lists
    every field that differs), with a count of the others."""
    first, *others = message.split(REASON_SEPARATOR)
    return first + (f" (and {len(others)} more in {RESULTS_FILE})" if others else "")


def _run_status(rows, engine: str) -> tuple[str, str] | None:
    """(status, its first reason) when ``engine``'s run did not end ``ok``, else None."""
    found = rows[(rows["engine"] == engine) & (rows["metric"] == RUN_STATUS_METRIC)]
    if found.empty:
        return None
    return found.iloc[0]["status"], _first_reason(found.iloc[0]["message"])


def _failed(rows, engine: str, metric: str):
    """The row of ``engine``'s ``metric`` when its value is beyond its tolerance (``passed``
    False, whatever the run's status), else None."""
    found = rows[(rows["engine"] == engine) & (rows["metric"] == metric)]
    bad = found[found["passed"].map(lambda passed: passed is False)]
    return None if bad.empty else bad.iloc[0]


def pair_verdict(rows, a: str, b: str) -> str:
    """``a`` and ``b``'s first tier (``TIERS``) where a row of one of them failed, with the
    row's message (and the run's status when it did not end ``ok``); else, when a run did not
    end ``ok`` (it could not run the model, or not to the end), that status; else
    ``AGREEING``."""
    for number, tier in enumerate(TIERS, start=1):
        for metric in tier:
            for engine in (a, b):
                row = _failed(rows, engine, metric)
                if row is not None:
                    run = _run_status(rows, engine)
                    status = f" ({run[0]})" if run else ""
                    why = row["message"] or f"{metric} {row['value_text']}"
                    return f"tier {number} ({metric}): {engine}{status}: {why}"
    for engine in (a, b):
        run = _run_status(rows, engine)
        if run is not None:
            return f"no tier row failed, but {engine}'s run is {': '.join(filter(None, run))}"
    return AGREEING


def verdicts(results: Path) -> list[str]:
    """One line per engine pair of the run folder's results, ``a vs b: <pair_verdict>``; for
    a run in one engine, that engine's own (``a: <verdict>``: tiers 1 to 3 are against the
    reference side)."""
    from validation.report.read import read_results

    rows = read_results(results)
    engines = list(dict.fromkeys(rows["engine"]))
    if len(engines) == 1:
        return [f"{engines[0]}: {pair_verdict(rows, engines[0], engines[0])}"]
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
    scheduler: str | None = None,
) -> int:
    """The whole command (module docstring); the exit code, as ``physval run``'s. ``jobs``,
    ``job_timeout``, ``scheduler``: as ``run``'s ``--jobs``, ``--job-timeout``, ``--scheduler``."""
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
            scheduler=scheduler,
            history="none",
            job_timeout=job_timeout,
            extra_files={SCENE_FILE: scene.read_text()},
        )
    if code == EXIT_BAD_INPUT or not (out / RESULTS_FILE).is_file():
        return code
    print(VERDICT_TITLE)
    print("\n".join(verdicts(out / RESULTS_FILE)))
    return code
