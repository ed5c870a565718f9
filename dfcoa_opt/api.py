"""The Python facade: load a scenario, run a controller, read the metrics, plot.

Everything here is re-exported by :mod:`dfcoa_opt`, so a notebook needs one
import::

    import dfcoa_opt as d

    s = d.load("scenarios/dfcoa_s1.toml")
    r = d.run(s, "dfcoa")
    r.metrics["outcome"]          # 'success'
    r.plot()                      # a matplotlib Figure
    res = d.sweep({"scenarios": ["scenarios/dfcoa_s1.toml"],
                   "controllers": ["dfcoa", "goto_slot"], "seeds": 5})
    res.table()                   # one row per run (a DataFrame with pandas)
    res.report()                  # report.md, paired statistics and figures

The facade calls the same code as the ``dfcoa`` command line
(:func:`~dfcoa_opt.scenario.loader.load_scenario`,
:class:`~dfcoa_opt.sim.simulator.Simulator`, :func:`~dfcoa_opt.metrics.summary`,
:mod:`~dfcoa_opt.viz.plotting`), so a run from Python gives the same numbers, bit
for bit, as ``dfcoa run`` with the same scenario, controller and seed.
"""

from __future__ import annotations

import warnings
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from typing import TYPE_CHECKING, Any

from dfcoa_opt.control.registry import register
from dfcoa_opt.core.errors import DfcoaError

if TYPE_CHECKING:
    from matplotlib.figure import Figure

    from dfcoa_opt.scenario.scenario import Scenario
    from dfcoa_opt.sim.log import RunLog

__all__ = ["Results", "Run", "controllers", "load", "register", "report", "run", "run_batch",
           "sweep"]


def load(path: str | Path, *, seed: int | None = None,
         overrides: Mapping[str, Any] | None = None, **keys: Any) -> Scenario:
    """Load and validate a scenario file.

    Args:
        path: The ``.toml`` file.
        seed: Replaces the file's ``seed``.
        overrides: Dotted keys set before validation, e.g.
            ``{"leader.speed": 0.4, "controllers.dfcoa.k1": 2.0}``.
        **keys: More overrides as keywords, ``__`` standing for the dot:
            ``load(path, t_max=30, leader__speed=0.4)``.

    Returns:
        The :class:`~dfcoa_opt.scenario.scenario.Scenario`.

    Raises:
        ScenarioError: A bad file or key, in one line naming the file, the key
            and the problem (as ``dfcoa run`` prints it).

    Examples:
        >>> import dfcoa_opt as d
        >>> s = d.load("scenarios/dfcoa_s1.toml", t_max=20.0)
        >>> s.spec.t_max
        20.0
    """
    from dfcoa_opt.scenario.loader import load_scenario

    merged = {**dict(overrides or {}), **{k.replace("__", "."): v for k, v in keys.items()}}
    return load_scenario(path, seed, merged or None)


def controllers() -> list[str]:
    """Ids of every registered controller, sorted (built-in, entry points, ``register``-ed).

    A safety filter is added to any of them as ``"<controller>+<filter>"``, e.g.
    ``"goto_slot+cbf"``.

    Examples:
        >>> import dfcoa_opt as d
        >>> "dfcoa" in d.controllers()
        True
    """
    from dfcoa_opt.control.registry import available

    return available()


def run(scenario: Scenario | str | Path, controller: str | Any,
        seed: int | None = None, record_scans: bool = False) -> Run:
    """Simulate one scenario with one controller.

    Args:
        scenario: A loaded scenario, or the path of a scenario file.
        controller: A registry id (see :func:`controllers`; ``"a+cbf"`` adds a
            filter), built with the scenario's ``[controllers.<id>]`` parameters;
            or a controller object (see README, "Add your own controller").
        seed: The run's seed (default: the scenario's). It means what
            ``dfcoa run --seed`` and a sweep's seed mean: a path is loaded with
            it, and a loaded scenario whose world is drawn from the seed (a
            ``[world.clutter]`` field without its own seed) is drawn again for
            it, with the same overrides. One ``numpy.random.Generator`` made
            from it is the run's only random source: the same seed gives the
            same run, bit for bit, from every entry point.
        record_scans: Keep the robots' LiDAR scans in ``log.scan`` (for
            :meth:`Run.to_mcap`); the run is the same either way.

    Returns:
        The :class:`Run`: ``.scenario`` (the one that ran, drawn for ``seed``),
        ``.log`` (every array), ``.metrics``, ``.plot()``, ``.animate(path)``,
        ``.to_mcap(path)``.

    Raises:
        ScenarioError: A bad scenario file or controller parameter.
        UnknownNameError: An unknown controller id, with a "did you mean" hint.
        ControllerError: The controller returned a bad command.

    Examples:
        >>> import dfcoa_opt as d
        >>> r = d.run("scenarios/example_empty.toml", "goto_slot", seed=1)
        >>> r.metrics["outcome"]
        'success'
    """
    from dfcoa_opt.control.registry import build_controller
    from dfcoa_opt.sim.simulator import Simulator

    sc = scenario if not isinstance(scenario, str | Path) else load(scenario, seed=seed)
    if isinstance(controller, str):
        ctrl = build_controller(controller, sc.spec.controllers, sc.source)
    elif callable(getattr(controller, "act", None)):
        ctrl = controller
    else:
        raise DfcoaError(f"run: controller must be a registry id or an object with act(obs), "
                         f"got {type(controller).__name__}")
    sim = Simulator(sc, ctrl, seed, record_scans)
    return Run(sim.scenario, sim.run())


def run_batch(scenario: Scenario | str | Path, controller: str | Any,
              seeds: Sequence[int]) -> list[Run]:
    """Simulate one scenario with one controller for several seeds, stepped as one batch.

    The runs are stepped together (one array of ``len(seeds) x N`` robots), so
    the simulator's per-step overhead is paid once for all of them; each run is
    the run :func:`run` gives for its seed, bit for bit (the same log digest and
    metrics as ``dfcoa run --seed``), with its own world drawn for its seed.

    Args:
        scenario: A loaded scenario, or the path of a scenario file.
        controller: A registry id (``"a+cbf"`` adds a filter), or a controller
            object: a batched one (``batched = True``), or a list of one
            object per seed.
        seeds: The runs' seeds.

    Returns:
        One :class:`Run` per seed, in the order of ``seeds``.

    Raises:
        ScenarioError: A bad scenario file or controller parameter.
        UnknownNameError: An unknown controller id.
        ControllerError: The controller returned a bad command.
        DfcoaError: No seeds, or an unbatched controller object for several seeds.

    Examples:
        >>> import dfcoa_opt as d
        >>> runs = d.run_batch("scenarios/example_empty.toml", "goto_slot", range(4))
        >>> [r.log.meta["seed"] for r in runs]
        [0, 1, 2, 3]
    """
    from dfcoa_opt.sim.batch import BatchSimulator
    from dfcoa_opt.sim.simulator import batch_controllers

    seeds = [int(s) for s in seeds]
    if not seeds:
        raise DfcoaError("run_batch: seeds is empty")
    sc = scenario if not isinstance(scenario, str | Path) else load(scenario, seed=seeds[0])
    if isinstance(controller, str):
        ctrl: Any = batch_controllers(controller, sc, len(seeds))
    elif isinstance(controller, Sequence) or callable(getattr(controller, "act", None)):
        ctrl = controller
    else:
        raise DfcoaError(f"run_batch: controller must be a registry id, a controller object or "
                         f"a list of them, got {type(controller).__name__}")
    sim = BatchSimulator(sc, ctrl, seeds)
    return [Run(s, log) for s, log in zip(sim.scenarios, sim.run_all(), strict=True)]


@dataclass
class Run:
    """One simulated run: the scenario, its log, its metrics and its plots.

    Attributes:
        scenario: The scenario that was run.
        log: Every logged array (:class:`~dfcoa_opt.sim.log.RunLog`: ``t``,
            ``pose`` ``(T, N, 3)``, ``slots``, ``leader``, ...; ``log.meta`` holds
            the run's facts such as ``seed`` and ``time_to_goal``).
    """

    scenario: Scenario
    log: RunLog = field(repr=False)

    @cached_property
    def metrics(self) -> dict[str, Any]:
        """Every metric of the run (``outcome``, ``fce_rms``, ...; ``docs/metrics.md``).

        The scenario's ``[metrics]`` settings apply, as in ``dfcoa run``.
        """
        from dfcoa_opt import metrics

        return metrics.summary(self.log, self.scenario.spec.metrics)

    def plot(self, path: str | Path | None = None) -> Figure:
        """The map, the trajectories, the leader and the final formation.

        Args:
            path: Also save the figure there as a PNG (folders are created).

        Returns:
            The matplotlib ``Figure`` (shown inline in a notebook).
        """
        from dfcoa_opt.viz import plotting
        from dfcoa_opt.viz.layout import save_png

        sc = self.scenario
        fig = plotting.run_figure(self.log, sc.world.grid, sc.spec.leader.goal,
                                  sc.spec.leader.start, shapes=sc.world.shapes,
                                  metrics=sc.spec.metrics)
        if path is not None:
            save_png(fig, path)
        return fig

    def animate(self, path: str | Path, fps: float = 10.0, max_frames: int = 200) -> Figure:
        """Write a GIF animation of the run (as ``dfcoa run --animate``).

        Args:
            path: The ``.gif`` file (folders are created).
            fps: Frames per second.
            max_frames: Most frames; the steps are subsampled evenly.

        Returns:
            The animation's matplotlib ``Figure``, at its last frame.

        Raises:
            DfcoaError: ``path`` does not end in ``.gif``.
        """
        from dfcoa_opt.viz import animation

        if not str(path).lower().endswith(".gif"):
            raise DfcoaError(f"animate: '{path}' must end in .gif")
        sc = self.scenario
        out: list[Figure] = []
        animation.animate_run(self.log, sc.world.grid, path, sc.spec.leader.goal, fps,
                              max_frames, sc.spec.leader.start, shapes=sc.world.shapes,
                              figure=out, metrics=sc.spec.metrics)
        return out[0]

    def to_mcap(self, path: str | Path) -> Path:
        """Write the run as a rosbag2 MCAP file for Foxglove and RViz 2 (docs/ros.md).

        Scans are in it when the run recorded them (``run(..., record_scans=True)``).
        Needs the ``ros`` extra.

        Args:
            path: The ``.mcap`` file (folders are created).

        Returns:
            ``path``.
        """
        from dfcoa_opt.viz.mcap import write_mcap

        return write_mcap(self.log, path, self.scenario.world)


def sweep(spec: str | Path | Mapping[str, Any], out: str | Path | None = None, *,
          jobs: int | None = None, seeds: int | None = None,
          overrides: Mapping[str, Any] | None = None, rerun: bool = False,
          progress: bool | None = None) -> Results:
    """Run a sweep (controllers x scenarios x seeds) as ``dfcoa bench`` does.

    Runs already in ``out`` are reused (the same scenario file, overrides and
    code), so calling it again resumes.

    Args:
        spec: A sweep file, or a dict with its keys (``scenarios`` (patterns,
            relative to the working folder), ``controllers``, ``seeds``,
            ``grid``, ``variants``, ``baseline``, ``ladder``;
            ``docs/benchmarking.md``).
        out: Results folder. Default: for a sweep file ``results/<sweep name>``
            (as ``dfcoa bench``); for a dict ``results/<name>-<8 hex digits>``
            (the name, ``"sweep"`` unless the dict gives one, and a hash of the
            dict, ``seeds`` and ``overrides``:
            :func:`~dfcoa_opt.bench.harness.default_folder`), so the same dict
            resumes in its folder and a different one never shares a folder
            with it.
        jobs: Worker processes (default: one per core). 1 runs every run in
            this process, which is also what happens, with a warning, when a
            controller of the sweep was registered in this process only (a
            notebook cell): worker processes could not build it.
        seeds: Replace the sweep's seed count.
        overrides: Dotted scenario keys set in every run.
        rerun: Run everything again.
        progress: Progress bar (default: only on a terminal).

    Returns:
        The :class:`Results`.

    Raises:
        ScenarioError: A bad sweep or scenario key, before any run starts.

    Examples:
        >>> import dfcoa_opt as d
        >>> res = d.sweep({"scenarios": ["scenarios/example_empty.toml"],
        ...                "controllers": ["goto_slot"], "seeds": 2}, "/tmp/demo")
        >>> [r["outcome"] for r in res.rows]
        ['success', 'success']
    """
    from dfcoa_opt.bench.executors import ExecutorConfig
    from dfcoa_opt.bench.harness import default_folder, run_sweep
    from dfcoa_opt.bench.sweep.expand import load_sweep, sweep_from_dict
    from dfcoa_opt.control.registry import known_to_workers

    if isinstance(spec, Mapping):
        sw = sweep_from_dict(spec, ".", seeds, overrides)
    else:
        sw = load_sweep(spec, seeds, overrides)
    local = sorted({v.controller for v in sw.variants if not known_to_workers(v.controller)})
    if local and jobs != 1:
        warnings.warn(f"sweep: {', '.join(local)} registered in this process only (not a "
                      "built-in or an entry point), so the sweep runs here, one run at a "
                      "time (jobs=1)", stacklevel=2)
        jobs = 1
    folder = Path(out) if out is not None else default_folder(sw, seeds, overrides)
    run_sweep(sw, folder, ExecutorConfig("process", jobs), rerun=rerun, progress=progress)
    return Results(folder)


def report(results: str | Path | Results, out: str | Path | None = None,
           baseline: str | None = None) -> list[Path]:
    """Tables and figures of a results folder, as ``dfcoa report`` (never simulates).

    Args:
        results: The results folder (or :class:`Results`).
        out: Output folder (default ``<results>/report``).
        baseline: Variant the others are compared with, pairwise by seed
            (default: the sweep's ``baseline``; ``""`` for none).

    Returns:
        The written files (``report.md`` first).

    Examples:
        >>> import dfcoa_opt as d
        >>> d.report("results/examples")[0].name      # after d.sweep(..., "results/examples")
        'report.md'
    """
    from dfcoa_opt.bench.report.document import make_report

    folder = results.folder if isinstance(results, Results) else Path(results)
    return make_report(folder, out, baseline=baseline)


@dataclass
class Results:
    """A results folder written by :func:`sweep` (or ``dfcoa bench``).

    Attributes:
        folder: The folder (``manifest.json``, ``rows/``, ``logs/``, ``results.csv``).
    """

    folder: Path

    @property
    def rows(self) -> list[dict[str, Any]]:
        """One dict per run: its keys (``scenario``, ``variant``, ``seed``, ...), its metrics."""
        from dfcoa_opt.bench.results.store import CSV_FIELDS, ResultsStore

        out = []
        for r in ResultsStore(self.folder).rows():
            row = {k: r.get(k) for k in CSV_FIELDS}
            row.update(r.get("metrics") or {})
            out.append(row)
        return out

    def table(self) -> Any:
        """:attr:`rows` as a pandas DataFrame when pandas is installed, else the list."""
        try:
            import pandas as pd
        except ImportError:
            return self.rows
        return pd.DataFrame(self.rows)

    def report(self, out: str | Path | None = None, baseline: str | None = None) -> list[Path]:
        """:func:`report` of this folder."""
        return report(self, out, baseline)

    def log(self, scenario: str, variant: str, seed: int) -> RunLog:
        """The stored log of one run (:class:`~dfcoa_opt.sim.log.RunLog`).

        Raises:
            DfcoaError: No such run in the folder, naming what is there.
        """
        from dfcoa_opt.bench.results.store import ResultsStore
        from dfcoa_opt.sim.log import RunLog

        rows = ResultsStore(self.folder).rows()
        hit = [r for r in rows if (r["scenario"], r["variant"], r["seed"])
               == (scenario, variant, seed) and r.get("log")]
        if not hit:
            have = sorted({(r["scenario"], r["variant"]) for r in rows})
            raise DfcoaError(f"{self.folder}: no logged run {scenario} / {variant} / seed "
                             f"{seed}; it has {have}")
        return RunLog.load(self.folder / hit[0]["log"])
