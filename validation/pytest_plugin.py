"""pytest plugin (entry point ``pytest11``): ``pytest --physval [PATHS]`` runs scenes as tests.

One item per (scene, engine spec), node id ``<scene file>::<spec label>`` (e.g.
``scenarios/formulas/projectile.yaml::mujoco(integrator=RK4)``). An item runs its job in the
pytest process as ``physval run`` does (``run_job``, ``compare_scene``, ``apply_known``); it
fails when a row of its case is bad (failed, unstable, model_mismatch, error, crashed,
timed_out: the job runs in a worker process, ``--job-timeout`` its time limit), showing each
such row against its tolerance; a case whose every bad row is a known finding is xfail
(strict=False: a known finding that passes again reads XPASS, not a failure). ``-k``, ``-x``,
``--junitxml`` and pytest-xdist's ``-n`` work as for any test.

``pytest --physval-conformance ENGINE_SPEC`` (repeatable) adds one item per conformance check
of that engine (``validation.jobs.conformance``), node id ``conformance[<spec>]::<check>``, to
whatever else is collected; the ``physval_conformance`` fixture is ``run_conformance`` itself
(``physval_conformance("myengine")`` -> the list of ``CheckResult``), for an adapter's own
test suite.

Without ``--physval`` the plugin only adds its options and fixture: nothing of physval beyond
this module is imported, and nothing is collected. With it, the scene paths (default: ``./scenarios``
or the bundled library) replace pytest's default test paths; paths given as pytest
arguments are collected too.
"""

from __future__ import annotations

import os
from pathlib import Path

import pytest

OPTION = "--physval"
DEST = "physval"

PLUGIN_NAME = "physval-scenes"
"""The name of the collecting plugin, registered only when ``--physval`` is given."""


def pytest_addoption(parser: pytest.Parser) -> None:
    group = parser.getgroup("physval", "physval scenes as tests")
    group.addoption(
        OPTION,
        nargs="*",
        default=None,
        dest=DEST,
        metavar="PATH",
        help="run physval scenes (files or folders; default ./scenarios or the bundled "
        "library), one test per (scene, engine spec)",
    )
    _add_conformance_option(group)
    group.addoption(
        JOB_TIMEOUT_OPTION,
        type=float,
        default=None,
        dest=JOB_TIMEOUT_DEST,
        metavar="SECONDS",
        help="each scene item's and conformance check's time limit (physval run "
        "--job-timeout: default derived from the job's expected time; 0: none); an item "
        "past it, or whose engine crashed, fails with status timed_out or crashed",
    )


JOB_TIMEOUT_OPTION = "--job-timeout"
JOB_TIMEOUT_DEST = "physval_job_timeout"


def _job_timeout(node) -> float | None:
    """``--job-timeout`` of the session ``node`` belongs to (None: derived, ``time_limit``)."""
    return node.config.getoption(JOB_TIMEOUT_DEST)


CONFORMANCE_OPTION = "--physval-conformance"
CONFORMANCE_DEST = "physval_conformance"


@pytest.fixture
def physval_conformance():
    """``run_conformance(engine_spec, only=None)``: every conformance check's ``CheckResult``."""
    from validation.jobs.conformance import run_conformance

    return run_conformance


def _add_conformance_option(group) -> None:
    group.addoption(
        CONFORMANCE_OPTION,
        action="append",
        default=None,
        dest=CONFORMANCE_DEST,
        metavar="ENGINE_SPEC",
        help="check an engine adapter against the adapter contract, one test per check "
        "(repeatable)",
    )


class ConformanceFailedError(Exception):
    """A conformance check found problems (the text lists them)."""


class ConformanceItem(pytest.Item):
    """One conformance check of one engine spec."""

    def __init__(self, *, spec: str, check: str, **kwargs):
        super().__init__(**kwargs)
        self.spec, self.check = spec, check

    def runtest(self) -> None:
        from validation.jobs.conformance import isolated_conformance

        (result,) = isolated_conformance(self.spec, [self.check], _job_timeout(self))
        if not result.passed:
            raise ConformanceFailedError(
                "\n".join([f"{self.spec} {self.check}:", *result.problems])
            )

    def repr_failure(self, excinfo, style=None):
        if isinstance(excinfo.value, ConformanceFailedError):
            return str(excinfo.value)
        return super().repr_failure(excinfo, style)

    def reportinfo(self):
        return self.path, None, f"conformance {self.spec} · {self.check}"


class ConformanceCollector:
    """Adds the ``--physval-conformance`` items after the rest is collected."""

    def __init__(self, specs: list[str]):
        self.specs = specs

    def pytest_collection_modifyitems(self, session, config, items) -> None:
        from validation.jobs.conformance import CHECKS

        items.extend(
            ConformanceItem.from_parent(
                session, name=f"conformance[{spec}]::{check}", spec=spec, check=check
            )
            for spec in self.specs
            for check in CHECKS
        )


def pytest_configure(config: pytest.Config) -> None:
    """With ``--physval``: collect the scene paths and register the collector; with
    ``--physval-conformance``: register the conformance items."""
    timeout = config.getoption(JOB_TIMEOUT_DEST)
    if timeout is not None and not 0 <= timeout < float("inf"):
        raise pytest.UsageError(
            f"{JOB_TIMEOUT_OPTION}: expected a number of seconds >= 0 (0: no time limit); "
            f"got {timeout}"
        )
    specs = config.getoption(CONFORMANCE_DEST)
    if specs:
        config.pluginmanager.register(ConformanceCollector(specs), "physval-conformance")
    given = config.getoption(DEST)
    if given is None:
        return
    from validation.engines.sabotage import SabotageError, chosen
    from validation.scenario import default_scenario_paths

    try:
        chosen()  # PHYSVAL_SABOTAGE (validation.engines.sabotage) checked before any scene
    except SabotageError as error:
        raise pytest.UsageError(str(error)) from None
    roots = [Path(p) for p in given] or default_scenario_paths()
    explicit = config.args if config.args_source == pytest.Config.ArgsSource.ARGS else []
    config.args = [str(root) for root in roots] + [a for a in explicit if a not in given]
    config.pluginmanager.register(SceneCollector(roots), PLUGIN_NAME)


class SceneCollector:
    """The hooks that turn the scene files under the ``--physval`` paths into ``SceneFile``s:
    exactly the files ``physval run`` reads (``scenario_files``, the one collection of both),
    so a dangling link or a FIFO named ``*.yaml``, which pytest's folders pass over, is an item
    whose collection error is ``run``'s refusal."""

    def __init__(self, roots: list[Path]):
        from validation.scenario import scenario_files

        self.roots = [root.resolve() for root in roots]
        self.files = {Path(os.path.abspath(f)) for f in scenario_files(_present(roots))}
        self.folders = {file.parent for file in self.files}

    def _under_roots(self, path: Path) -> bool:
        path = path.resolve()
        return any(path == root or root in path.parents for root in self.roots)

    def pytest_collect_file(self, file_path: Path, parent: pytest.Collector):
        if Path(os.path.abspath(file_path)) in self.files:
            return SceneFile.from_parent(parent, path=file_path)
        return None

    def pytest_collect_directory(self, path: Path, parent: pytest.Collector):
        if self._under_roots(path) or Path(os.path.abspath(path)) in self.folders:
            return SceneFolder.from_parent(parent, path=path)
        return None


def _present(roots: list[Path]) -> list[Path]:
    """The roots that exist (a missing one is pytest's "file or directory not found")."""
    return [root for root in roots if os.path.lexists(root)]


class SceneFolder(pytest.Dir):
    """A folder under the ``--physval`` paths: pytest's own, plus the scene files in it that
    are not regular files (pytest collects regular files only), as ``physval run`` lists them."""

    def collect(self):
        yield from super().collect()
        collector = self.config.pluginmanager.get_plugin(PLUGIN_NAME)
        here = Path(os.path.abspath(self.path))
        for file in sorted(collector.files):
            if file.parent == here and not file.is_file():
                yield SceneFile.from_parent(self, path=file)


class SceneFailedError(Exception):
    """A case with bad rows that are not all known findings (the text lists them)."""


class KnownFailureError(Exception):
    """A case whose every bad row is a known finding (expected to fail: xfail)."""


def _known_marker(scenario, spec_label: str) -> pytest.MarkDecorator | None:
    """xfail for the findings the scene declares on this spec; only ``KnownFailureError`` counts
    as the expected failure, so a new failure of the same spec still fails."""
    from validation.scenario.engine_spec import parse_engine_spec

    reasons = [
        finding.reason
        for finding in scenario.known
        if parse_engine_spec(finding.engine).label == spec_label
    ]
    if not reasons:
        return None
    return pytest.mark.xfail(reason="; ".join(reasons), raises=KnownFailureError, strict=False)


class SceneFile(pytest.File):
    """One scene file: planned as ``physval run`` plans it, one item per engine spec. Runs are
    kept per file, so that a spec's ``divergence`` can use the scene's reference run (the
    first engine that ran) without running it twice in one process."""

    def collect(self):
        from validation.jobs.plan import BadInputError, plan_run

        try:
            plan = plan_run([self.path], None, None, None)
        except BadInputError as error:
            raise self.CollectError(str(error)) from None
        self.scene, self.specs = plan.scenes[0]
        self._done: dict[int, tuple] = {}
        for index, spec in enumerate(self.specs):
            item = SceneItem.from_parent(self, name=spec.label, index=index)
            marker = _known_marker(self.scene.scenario, spec.label)
            if marker is not None:
                item.add_marker(marker)
            yield item

    def job(self, index: int) -> tuple:
        """(run, measurements) of the spec at ``index``, run once per process, in a worker
        process of its own (``executor.run_jobs``): an engine that crashes or hangs fails its
        item (``crashed``, ``timed_out``), never the session."""
        from validation.jobs.executor import run_jobs
        from validation.jobs.plan import expected_cost
        from validation.jobs.run import lost_run, run_job

        if index not in self._done:
            (self._done[index],) = run_jobs(
                run_job,
                [(self.scene, self.specs[index])],
                1,
                lost=lost_run,
                cost=lambda job: expected_cost(job[0].scenario),
                job_timeout=_job_timeout(self),
            )
        return self._done[index]

    def rows(self, index: int) -> list[dict]:
        """The judged rows of the spec at ``index``, as ``physval run`` writes them."""
        return spec_rows(self.scene, self.specs, index, self.job)


def spec_rows(scene, specs: list, index: int, job) -> list[dict]:
    """The rows ``physval run`` writes for ``specs[index]`` of ``scene``, known findings applied;
    ``job(i)`` gives spec i's (run, measurements). Its ``divergence`` is taken from the scene's
    reference, the first spec whose run has a recording, as ``compare_scene`` does."""
    from validation.measure.comparator import compare_scene
    from validation.nightly.known import apply_known

    own = job(index)
    chosen = [own]
    if own[0].recording is not None:
        earlier = (job(i) for i in range(index))
        reference = next((done for done in earlier if done[0].recording is not None), None)
        chosen = chosen if reference is None else [reference, own]
    compared = compare_scene(scene, [run for run, _ in chosen], [found for _, found in chosen])
    label = specs[index].label
    return apply_known([row for row in compared if row["engine"] == label], scene.scenario)


class SceneItem(pytest.Item):
    """One (scene, engine spec)."""

    def __init__(self, *, index: int, **kwargs):
        super().__init__(**kwargs)
        self.index = index

    def runtest(self) -> None:
        from validation.nightly.cases import SKIPPED, group_cases

        (case,) = group_cases(self.parent.rows(self.index))
        if case.bad_rows:
            raise SceneFailedError(failure_text(case))
        if case.rows_of(SKIPPED):
            raise KnownFailureError("; ".join(case.known_reasons))

    def repr_failure(self, excinfo, style=None):
        if isinstance(excinfo.value, SceneFailedError | KnownFailureError):
            return str(excinfo.value)
        return super().repr_failure(excinfo, style)

    def reportinfo(self):
        return self.path, None, f"{self.parent.scene.name} · {self.name}"


def failure_text(case) -> str:
    """Each bad row against its tolerance, then the known rows of the case."""
    from validation.nightly.cases import SKIPPED, describe, reason

    lines = [f"{case.scenario} · {case.engine}: {len(case.bad_rows)} bad row(s)"]
    lines += [f"  {describe(row)}" for row in case.bad_rows]
    known = case.rows_of(SKIPPED)
    lines += ["known findings of this case (not counted):"] if known else []
    lines += [f"  {describe(row)} ({reason(row)})" for row in known]
    return "\n".join(lines)
