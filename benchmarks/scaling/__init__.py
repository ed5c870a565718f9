"""Scaling study (issue 7): cost per step of every registered controller against team size N.

Run ``python -m benchmarks.scaling`` (the command line, ``__main__``; writes
``benchmarks/scaling.md``, ``scaling.csv`` and ``scaling.png``). Imports run one way:
:mod:`~benchmarks.scaling.samples` (the data types) and
:mod:`~benchmarks.scaling.scenario` (the open-field scenario) import nothing of the
study; :mod:`~benchmarks.scaling.measure` (timing), :mod:`~benchmarks.scaling.memory`
(peak memory, one ``python -m benchmarks.scaling.memory`` subprocess per run) and
:mod:`~benchmarks.scaling.report` (summary, CSV, plot, stdout) import those two;
:mod:`~benchmarks.scaling.markdown` (``scaling.md``) imports the report; ``__main__``
imports them all, and nothing imports it.
"""
