"""``dfcoa tune``: the same tuning budget for every method, on training seeds only.

A *tuning sweep* is a sweep file with ``split = "train"`` and a ``[tune]`` table
(:class:`TuneSpec`); its variants are the methods to tune and its runs for
one variant (scenarios x training seeds, with the sweep's settings) are what
every trial of that variant simulates. For each variant:

1. the tunable parameters are those its classes declare
   (:func:`~dfcoa_opt.control.registry.controller_tunables`; a key the variant
   sets itself stays fixed);
2. trial 0 runs the defaults, then Optuna's TPE sampler proposes the next
   parameters from the finished trials. The sampler of trial ``k`` is seeded
   with ``sampler_seed * 100003 + k`` and rebuilt from the journal of finished
   trials, so the proposals are a pure function of the seed and the results:
   a killed ``dfcoa tune`` resumes where it stopped and proposes what an
   uninterrupted one would have;
3. a trial's runs go through the sweep executors (:func:`run_sweep`: batches,
   ``--jobs``, Dask) into ``RESULTS/<variant>/``, where finished runs are kept
   (their logs compacted: tuning reads rows only);
4. the objective (:func:`objective`) is the collision-free success rate, with
   one tie breaker that never outweighs a success: the CVaR(0.9) of the
   formation centroid error;
5. the best trial (the highest objective, the earliest on a tie) becomes the
   variant ``<variant>@tuned`` in the variants file ``<out>/<variant>.toml``
   (:func:`variants_file_text`), with the budget, the seeds and the training
   success that produced it. Sweeps name it through ``variant_files``.
   With ``validation_trials = k`` and ``validation_repeat = m`` the last
   ``k x m`` trials' worth of runs go to validation instead: the ``k`` best
   training trials run again on ``m`` times as many of the scenarios'
   validation seeds (:func:`validation_runs`). The defaults are always a
   finalist, and the best finalist on validation replaces them only when it
   wins significantly more of the same validation worlds (:func:`choose`):
   the best of 30 trials on 25 worlds is partly the luckiest, and on
   ``reshape_passage`` such a winner solved 92.5 % of further validation
   worlds where the defaults solved 97 % (docs/heldout.md).

Every variant gets ``trials x runs per trial`` simulated runs: the budget is
counted in runs, not in seconds (docs/heldout.md).
"""

from __future__ import annotations

import json
import sys
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import Any

from dfcoa_opt.bench.executors import ExecutorConfig, kept_workers
from dfcoa_opt.bench.harness import run_sweep
from dfcoa_opt.bench.report.plots import as_number
from dfcoa_opt.bench.report.stats import McNemar, cvar, mcnemar_exact, mcnemar_greater_p
from dfcoa_opt.bench.results.logs import compact_log
from dfcoa_opt.bench.results.store import ResultsStore, display_path
from dfcoa_opt.bench.runner import is_success
from dfcoa_opt.bench.sweep.expand import load_sweep, sweep_from_dict
from dfcoa_opt.bench.sweep.specs import RunSpec, Sweep, canonical, safe_name
from dfcoa_opt.bench.sweep.variants import Variant
from dfcoa_opt.core.atomic import atomic_write
from dfcoa_opt.core.errors import DfcoaError, ScenarioError, did_you_mean
from dfcoa_opt.core.params import Tunable, build, param

#: The metric of the tie breaker and its scale: the CVaR of the formation centroid error
#: (m) over a trial's runs; a CVaR of this many metres or more costs the most.
TIE_METRIC, TIE_SCALE, TIE_ALPHA = "fce_rms", 1.0, 0.9
#: Suffix of a tuned variant's name.
TUNED = "@tuned"


@dataclass(frozen=True)
class TuneSpec:
    """The ``[tune]`` table of a tuning sweep."""

    trials: int = param(40, doc="Trials per variant, the defaults' included (each runs the "
                                "variant's runs of the sweep).", ge=1, le=10_000)
    sampler_seed: int = param(0, doc="Seed of the TPE sampler.", ge=0)
    startup_trials: int = param(8, doc="Trials drawn at random before TPE models the results "
                                       "(the defaults' trial included).", ge=1)
    out: str = param("../heldout/tuned", doc="Folder of the variants files, relative to the "
                                             "sweep file.")
    validation_trials: int = param(0, doc="Finalists: the defaults and the best this many - 1 "
                                          "other training trials run again on validation "
                                          "seeds (the scenarios' [splits] validation range, "
                                          "from its start), and the best there is chosen "
                                          "(see validation_alpha). Their runs count in the "
                                          "budget: "
                                          "trials - validation_trials x validation_repeat "
                                          "trials train. 0: the best training trial is "
                                          "chosen.", ge=0)
    validation_repeat: int = param(1, doc="Each finalist runs on this many times as many "
                                          "validation seeds of a scenario as a trial has "
                                          "training seeds.", ge=1, le=100)
    validation_alpha: float = param(0.05, doc="The best finalist replaces the defaults only "
                                              "when McNemar's exact one-sided p, that it wins "
                                              "more of the same validation worlds than they "
                                              "do, is below this.", gt=0.0, le=1.0)


@dataclass(frozen=True)
class Trial:
    """One finished trial.

    Attributes:
        number: 0 (the defaults), 1, 2, ...
        params: Dotted key -> value.
        value: :func:`objective`.
        successes: Collision-free successes.
        runs: Runs of the trial.
        cvar_fce: The tie breaker's CVaR, m (``inf`` when a run has no value).
    """

    number: int
    params: dict[str, Any]
    value: float
    successes: int
    runs: int
    cvar_fce: float


@dataclass(frozen=True)
class TuneResult:
    """What :func:`tune_variant` did: the trials and the written variants file."""

    variant: str
    trials: tuple[Trial, ...]
    best: Trial
    path: Path
    ran: int
    validated: tuple[Trial, ...] = ()
    departure: McNemar | None = None


def objective(rows: Sequence[Mapping[str, Any]]) -> tuple[float, int, float]:
    """A trial's score from its rows: ``(value, successes, cvar_fce)``.

    ``value = s / n - min(CVaR_0.9(FCE) / 1 m, 1) / (2 n)`` with ``s`` the
    collision-free successes of the ``n`` runs: the success rate decides, and
    the tie breaker, below half a success, only orders trials with as many
    successes (a smaller worst-case formation error is better).
    """
    n = len(rows)
    if n == 0:
        raise DfcoaError("a trial with no runs has no score")
    wins = sum(is_success(r) for r in rows)
    fce = [as_number((r.get("metrics") or {}).get(TIE_METRIC)) for r in rows]
    tail = cvar(fce, TIE_ALPHA)
    value = wins / n - min(tail / TIE_SCALE, 1.0) / (2.0 * n)
    return value, wins, tail


def tuning_sweep(path: str | Path, trials: int | None = None) -> tuple[Sweep, TuneSpec]:
    """Read a tuning sweep: the sweep, checked to run on training seeds, and its ``[tune]``.

    Raises:
        ScenarioError: Not ``split = "train"``, a seed outside the training
            range, or a bad ``[tune]`` table (one line, naming the file and key).
    """
    sweep, spec = _checked(load_sweep(path))
    return sweep, (spec if trials is None else replace(spec, trials=trials))


def tuning_sweep_of(data: Mapping[str, Any], path: Path) -> tuple[Sweep, TuneSpec]:
    """:func:`tuning_sweep` of a tuning sweep's contents, as if read from ``path``.

    ``dfcoa compare --tune`` gives the contents of the published tuning sweep
    with its own controller as the only variant: the same seeds, settings and
    ``[tune]`` budget.

    Raises:
        ScenarioError: As :func:`tuning_sweep`.
    """
    return _checked(replace(sweep_from_dict(data, path.parent), source=str(path)))


def _checked(sweep: Sweep) -> tuple[Sweep, TuneSpec]:
    """The sweep, checked to run on training seeds, and its ``[tune]`` table built."""
    src = sweep.source
    if sweep.spec.split != "train":
        raise ScenarioError(src, "split", f"dfcoa tune tunes on training seeds only: set "
                                          f"split = \"train\" (got '{sweep.spec.split}')")
    table = sweep.spec.tune
    if not isinstance(table, Mapping):
        raise ScenarioError(src, "tune", "is required: a [tune] table (trials, sampler_seed, "
                                         "out)")
    spec = build(TuneSpec, table, src, "tune")
    if spec.validation_trials == 1:
        raise ScenarioError(src, "tune.validation_trials",
                            "1 finalist is the defaults alone: use 0 (no validation) or at "
                            "least 2")
    if spec.validation_trials * spec.validation_repeat >= spec.trials:
        key = "tune.validation_repeat" if spec.validation_repeat > 1 else "tune.validation_trials"
        raise ScenarioError(src, key,
                            f"{spec.validation_trials} finalists x {spec.validation_repeat} "
                            f"leave no training trial of the {spec.trials} trials: use "
                            "fewer than trials")
    return sweep, spec


def tunables_of(variant: Variant) -> list[Tunable]:
    """The keys a variant's trials search: its classes' tunables but those it sets itself."""
    from dfcoa_opt.control.registry import controller_tunables

    fixed = {k for k, _ in variant.overrides}
    return [t for t in controller_tunables(variant.controller) if t.key not in fixed]


def _distributions(params: Sequence[Tunable]) -> dict[str, Any]:
    from optuna.distributions import (
        CategoricalDistribution,
        FloatDistribution,
        IntDistribution,
    )

    out: dict[str, Any] = {}
    for t in params:
        if t.kind == "bool":
            out[t.key] = CategoricalDistribution([False, True])
        elif t.kind == "int":
            out[t.key] = IntDistribution(int(t.low), int(t.high), log=t.scale == "log")
        else:
            out[t.key] = FloatDistribution(float(t.low), float(t.high), log=t.scale == "log")
    return out


def propose(number: int, done: Sequence[Trial], params: Sequence[Tunable],
            spec: TuneSpec) -> dict[str, Any]:
    """The parameters of trial ``number``: the defaults first, then TPE's proposal.

    The sampler is rebuilt for every trial from the finished ones and a seed
    of its own, so the proposal depends only on them (resume-safe).
    """
    if number == 0:
        return {t.key: t.default for t in params}
    try:
        import optuna
    except ModuleNotFoundError:
        raise DfcoaError("dfcoa tune needs Optuna: pip install -e '.[tune]'") from None
    optuna.logging.set_verbosity(optuna.logging.WARNING)
    dists = _distributions(params)
    sampler = optuna.samplers.TPESampler(seed=spec.sampler_seed * 100003 + number,
                                         n_startup_trials=spec.startup_trials)
    study = optuna.create_study(direction="maximize", sampler=sampler)
    for t in done:
        study.add_trial(optuna.trial.create_trial(params=dict(t.params), distributions=dists,
                                                  value=t.value))
    return dict(study.ask(dists).params)


def trial_runs(base: Sequence[RunSpec], variant: str, number: int,
               params: Mapping[str, Any]) -> list[RunSpec]:
    """Trial ``number``'s runs: the variant's runs with ``params`` set, under their own name."""
    name = f"{variant}@trial{number:03d}"
    return [replace(r, overrides=canonical({**r.overrides_dict, **params}), variant=name)
            for r in base]


def _journal(root: Path) -> Path:
    return root / "trials.json"


def _identity(sweep: Sweep, variant: Variant, params: Sequence[Tunable],
              spec: TuneSpec) -> dict[str, Any]:
    """What a journal's trials depend on: another identity starts the trials over."""
    return {"sweep_sha256": sweep.sha256, "variant": variant.name,
            "controller": variant.controller, "overrides": dict(variant.overrides),
            "tunables": [asdict(t) for t in params], "sampler_seed": spec.sampler_seed,
            "startup_trials": spec.startup_trials, "runs": [r.key for r in
                                                          _base_runs(sweep, variant.name)]}


def _read_journal(root: Path, identity: Mapping[str, Any]) -> list[Trial]:
    try:
        data = json.loads(_journal(root).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return []
    if data.get("identity") != json.loads(json.dumps(identity)):
        return []
    return [Trial(**t) for t in data.get("trials", [])]


def _base_runs(sweep: Sweep, name: str) -> list[RunSpec]:
    return [r for r in sweep.runs if r.variant_name == name and r.ladder_value is None]


def tune_variant(sweep: Sweep, spec: TuneSpec, name: str, results: str | Path,
                 config: ExecutorConfig | None = None, out: str | Path | None = None,
                 progress: bool | None = None) -> TuneResult:
    """Tune one variant of a tuning sweep (module docstring) and write its variants file.

    Args:
        sweep: The tuning sweep (:func:`tuning_sweep`).
        spec: Its ``[tune]`` table.
        name: The variant to tune.
        results: Folder of the trials' runs and journals; the variant's go in
            ``results/<variant>/``.
        config: Executor of the runs.
        out: Folder of the variants file; default ``spec.out`` beside the sweep file.
        progress: Progress bars (default: when stdout is a terminal).

    Raises:
        DfcoaError: An unknown variant, or one with nothing to tune.
    """
    names = [v.name for v in sweep.variants]
    if name not in names:
        raise DfcoaError(f"{sweep.source}: --variant: '{name}' is not a variant of this sweep"
                         f"{did_you_mean(name, names)}; variants: {', '.join(names)}")
    variant = next(v for v in sweep.variants if v.name == name)
    params = tunables_of(variant)
    if not params:
        raise DfcoaError(f"{sweep.source}: variant '{name}' ({variant.controller}) declares no "
                         "tunable parameter (param(tune=...))")
    base = _base_runs(sweep, name)
    root = Path(results) / safe_name(name)
    store = ResultsStore(root)
    identity = _identity(sweep, variant, params, spec)
    training = replace(spec, trials=spec.trials - spec.validation_trials * spec.validation_repeat)
    done = _read_journal(root, identity)[:training.trials]
    config = config or ExecutorConfig()
    validated: list[Trial] = []
    test: McNemar | None = None
    choice = ""
    with kept_workers(config):
        ran = _trials(training, name, params, base, done, replace(sweep, runs=()), root, store,
                      identity, config, progress)
        best = max(done, key=lambda t: (t.value, -t.number))
        if spec.validation_trials:
            validated, outcomes, vran = _validate(sweep, spec, name, done, base, root, store,
                                                  config, progress)
            ran += vran
            number, leader, test = choose(validated, outcomes,
                                          {t.number: t.value for t in done},
                                          spec.validation_alpha)
            best = next(t for t in done if t.number == number)
            choice = _choice_text(number, leader, test)
            print(f"{name}: {choice}", file=sys.stderr)
    folder = Path(out) if out is not None else Path(sweep.source).parent / spec.out
    path = folder / f"{safe_name(name)}.toml"
    folder.mkdir(parents=True, exist_ok=True)
    atomic_write(path, variants_file_text(sweep, spec, variant, params, done, best, validated,
                                          choice))
    return TuneResult(name, tuple(done), best, path, ran, tuple(validated), test)


def choose(validated: Sequence[Trial], outcomes: Mapping[int, Sequence[bool]],
           train_value: Mapping[int, float], alpha: float) -> tuple[int, int, McNemar | None]:
    """The chosen finalist: the best on validation, if it beats the defaults significantly.

    The best finalist has the highest validation objective (then the higher
    training objective, then the earlier trial). It replaces the defaults
    (trial 0) only when McNemar's exact one-sided p-value, that it wins more
    of the same validation worlds than they do, is below ``alpha``
    (:func:`~dfcoa_opt.bench.report.stats.mcnemar_greater_p`): a winner's lead
    over the defaults must be more than the luck of being the best of many
    trials.

    Args:
        validated: The finalists' validation scores, the defaults among them.
        outcomes: Trial number -> collision-free success of each validation
            world, in the same world order for every finalist.
        train_value: Trial number -> training objective.
        alpha: Significance level of the departure from the defaults.

    Returns:
        The chosen trial number, the best finalist's, and its test against
        the defaults (``None`` when the best is the defaults).
    """
    best = max(validated, key=lambda t: (t.value, train_value[t.number], -t.number))
    if best.number == 0:
        return 0, 0, None
    test = mcnemar_exact(outcomes[best.number], outcomes[0])
    return (best.number if mcnemar_greater_p(test) < alpha else 0), best.number, test


def _choice_text(chosen: int, best: int, test: McNemar | None) -> str:
    """One line on :func:`choose`'s choice."""
    if test is None:
        return "the defaults are the best finalist on validation seeds"
    p = mcnemar_greater_p(test)
    lead = (f"trial {best} won {test.b10} validation worlds the defaults lost and lost "
            f"{test.b01} they won (one-sided p {p:.3g})")
    return f"{lead}: chosen" if chosen else f"{lead}: the defaults stay"


def validation_runs(base: Sequence[RunSpec], variant: str, trial: Trial,
                    repeat: int = 1) -> list[RunSpec]:
    """A training trial's runs moved to validation seeds, under their own name.

    A scenario with ``n`` training seeds gets the first ``repeat x n`` seeds
    of its ``[splits]`` validation range, so a finalist is scored on ``repeat``
    times as many worlds of each scenario as it trained on, none of them a
    training or test world.

    Raises:
        ScenarioError: A scenario declares no validation range.
    """
    from dfcoa_opt.bench.sweep.expand import check_split
    from dfcoa_opt.scenario.loader import load_scenario

    first: dict[str, int] = {}
    lowest: dict[str, int] = {}
    span: dict[str, int] = {}
    for r in base:
        lowest[r.scenario_file] = min(lowest.get(r.scenario_file, r.seed), r.seed)
    for r in base:
        span[r.scenario_file] = max(span.get(r.scenario_file, 0),
                                    r.seed - lowest[r.scenario_file] + 1)

    def seed_of(r: RunSpec, j: int) -> int:
        return first[r.scenario_file] + r.seed - lowest[r.scenario_file] + j * span[r.scenario_file]

    out = []
    for j in range(repeat):
        for r in base:
            if r.scenario_file not in first:
                scenario = load_scenario(r.scenario_file)
                bounds = scenario.spec.splits.range_of("validation")
                if bounds is None:
                    raise ScenarioError(r.scenario_file, "splits.validation",
                                        "is required by tune.validation_trials")
                first[r.scenario_file] = int(bounds[0])
                seeds = [seed_of(s, i) for i in range(repeat)
                         for s in base if s.scenario_file == r.scenario_file]
                check_split(scenario, "validation", seeds, r.scenario_file)
            out.append(replace(r, seed=seed_of(r, j),
                               variant=f"{variant}@validation{trial.number:03d}",
                               overrides=canonical({**r.overrides_dict, **trial.params})))
    return out


def _validate(sweep: Sweep, spec: TuneSpec, name: str, done: Sequence[Trial],
              base: Sequence[RunSpec], root: Path, store: ResultsStore, config: ExecutorConfig,
              progress: bool | None) -> tuple[list[Trial], dict[int, list[bool]], int]:
    """Score the defaults and the best other training trials on validation seeds.

    Finished validation runs are kept in the store like the trials' runs, so
    a resumed ``dfcoa tune`` simulates only what is missing.

    Returns:
        One :class:`Trial` per finalist (its number and parameters, the
        validation score), the defaults first; each finalist's success per
        validation world; the runs simulated.
    """
    others = sorted((t for t in done if t.number != 0), key=lambda t: (-t.value, t.number))
    finalists = [done[0], *others[:spec.validation_trials - 1]]
    runs = {t.number: validation_runs(base, name, t, spec.validation_repeat)
            for t in finalists}
    result = run_sweep(replace(sweep, runs=tuple(r for rs in runs.values() for r in rs)), root,
                       config, progress=progress)
    out, outcomes = [], {}
    for t in finalists:
        rows = [store.read_row(r.key) for r in runs[t.number]]
        if any(r is None for r in rows):
            raise DfcoaError(f"{root}: the validation of trial {t.number} has runs without "
                             "a row")
        value, wins, tail = objective(rows)  # type: ignore[arg-type]
        out.append(Trial(t.number, t.params, value, wins, len(rows), tail))
        outcomes[t.number] = [is_success(r) for r in rows]  # type: ignore[arg-type]
        print(f"{name}: trial {t.number} on validation seeds: {wins}/{len(rows)} succeeded",
              file=sys.stderr)
    return out, outcomes, result.ran


def _trials(spec: TuneSpec, name: str, params: Sequence[Tunable], base: Sequence[RunSpec],
            done: list[Trial], grown: Sweep, root: Path, store: ResultsStore,
            identity: Mapping[str, Any], config: ExecutorConfig, progress: bool | None) -> int:
    """Run the trials not in ``done`` yet (appended to it); the runs simulated."""
    ran = 0
    for k in range(len(done), spec.trials):
        proposal = propose(k, done, params, spec)
        runs = trial_runs(base, name, k, proposal)
        grown = grown.extended(runs)
        result = run_sweep(grown, root, config, progress=progress)
        ran += result.ran
        rows = [store.read_row(r.key) for r in runs]
        if any(r is None for r in rows):
            raise DfcoaError(f"{root}: trial {k} has runs without a row")
        for row in rows:  # tuning reads rows only: its logs keep their trajectories alone
            if row and row.get("log"):
                compact_log(root / str(row["log"]))
        value, wins, tail = objective(rows)  # type: ignore[arg-type]
        done.append(Trial(k, proposal, value, wins, len(runs), tail))
        atomic_write(_journal(root), json.dumps(
            {"identity": identity, "trials": [asdict(t) for t in done]}, indent=1,
            default=str) + "\n")
        best = max(done, key=lambda t: (t.value, -t.number))
        print(f"{name}: trial {k + 1}/{spec.trials}: {wins}/{len(runs)} succeeded; best "
              f"{best.successes}/{best.runs} (trial {best.number})", file=sys.stderr)
    return ran


def _toml_value(v: Any) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, (int, float)):
        return repr(v)
    if isinstance(v, str):
        return json.dumps(v)
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    raise TypeError(f"no TOML form for {v!r}")


def _seed_text(runs: Iterable[RunSpec]) -> str:
    seeds = sorted({r.seed for r in runs})
    return f"{seeds[0]}-{seeds[-1]}" if seeds == list(range(seeds[0], seeds[-1] + 1)) \
        else ",".join(map(str, seeds))


def variants_file_text(sweep: Sweep, spec: TuneSpec, variant: Variant,
                       params: Sequence[Tunable], trials: Sequence[Trial], best: Trial,
                       validated: Sequence[Trial] = (), choice: str = "") -> str:
    """The variants file of a tuned variant: ``[variants."<name>@tuned"]`` and how it was made.

    With ``validated`` (the finalists' validation scores) the file also says
    how many trials were re-scored, the chosen one's and the defaults'
    validation success, and ``choice``: why the chosen finalist was chosen
    (:func:`choose`).
    """
    base = _base_runs(sweep, variant.name)
    default = trials[0]
    scen = sorted({r.scenario for r in base})
    lines = [
        f"# The variant {variant.name} tuned by `dfcoa tune "
        f"{display_path(sweep.source)} --variant {variant.name}` (docs/heldout.md).",
        "# Budget: the same for every method, counted in simulated runs; training seeds only.",
        "# Written by dfcoa tune; sweeps name the variant through variant_files.",
        "",
        "[tuned]",
        f"variant = {_toml_value(variant.name)}",
        f"controller = {_toml_value(variant.controller)}",
        f"sweep = {_toml_value(display_path(sweep.source))}",
        f"sweep_sha256 = {_toml_value(sweep.sha256)}",
        f"split = {_toml_value(sweep.spec.split)}",
        f"scenarios = {_toml_value(scen)}",
        f"seeds = {_toml_value(_seed_text(base))}",
        f"trials = {spec.trials}",
        f"runs_per_trial = {len(base)}",
        f"budget_runs = {spec.trials * len(base)}",
        "sampler = \"TPE (optuna), trial 0 = the defaults\"",
        f"sampler_seed = {spec.sampler_seed}",
        f"startup_trials = {spec.startup_trials}",
        "objective = \"collision-free success rate; tie breaker: CVaR(0.9) of fce_rms\"",
        f"best_trial = {best.number}",
        f"train_success = {best.successes}",
        f"train_runs = {best.runs}",
        f"default_train_success = {default.successes}",
    ]
    if validated:
        chosen = next(t for t in validated if t.number == best.number)
        runs = validation_runs(base, variant.name, chosen, spec.validation_repeat)
        lines += [
            f"validation_trials = {len(validated)}",
            f"validation_seeds = {_toml_value(_seed_text(runs))}",
            f"validation_success = {chosen.successes}",
            f"validation_runs = {chosen.runs}",
            f"default_validation_success = {validated[0].successes}",
            f"validation_alpha = {_toml_value(spec.validation_alpha)}",
            f"choice = {_toml_value(choice)}",
        ]
    lines += [
        f"tuned = {_toml_value([t.key for t in params])}",
        "",
        f"[variants.\"{variant.name}{TUNED}\"]",
        f"controller = {_toml_value(variant.controller)}",
    ]
    values = {**dict(variant.overrides), **best.params}
    lines += [f"\"{k}\" = {_toml_value(v)}" for k, v in values.items()]
    return "\n".join(lines) + "\n"
