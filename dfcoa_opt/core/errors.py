"""Error types of the toolkit.

Every error a user can cause by bad input is a :class:`DfcoaError`. Its string
form is one line, ``FILE: KEY.PATH: problem``, which the CLI prints as it is and
exits with code 2 (no traceback).
"""

from __future__ import annotations

import difflib
from collections.abc import Iterable


class DfcoaError(Exception):
    """Base class of every user-facing error; ``str(err)`` is a single line."""


class ScenarioError(DfcoaError):
    """A scenario, sweep or parameter file is invalid.

    Args:
        source: File name (or another description of where the data came from).
        key: Dotted key path inside the file, e.g. ``"robots.radius"``; empty
            for problems with the whole file.
        problem: What is wrong, in words.
    """

    def __init__(self, source: str, key: str, problem: str) -> None:
        self.source = printable(str(source))
        self.key = printable(key)
        self.problem = " ".join(str(problem).split())  # force a single line
        where = f"{self.source}: {self.key}: " if key else f"{self.source}: "
        super().__init__(where + self.problem)


def printable(text: str) -> str:
    """``text`` with every non-printable character (newline, tab, NUL, ...) as its escape.

    Keys come from the user's file, and a TOML key may hold any character; the
    message must stay one line and show what the file says.
    """
    if text.isprintable():
        return text
    return "".join(c if c.isprintable() else repr(c)[1:-1] for c in text)


class UnknownNameError(DfcoaError):
    """A name (controller id, planner, ...) that is not registered."""


def did_you_mean(name: str, choices: Iterable[str]) -> str:
    """Return a ``" (did you mean 'x'?)"`` hint, or ``""`` when nothing is close.

    Case does not count: a choice equal to ``name`` but for case comes first
    (``kP`` -> ``kp``), then the closest choice by :func:`difflib.get_close_matches`
    on the lowercased names.

    Args:
        name: The unknown name.
        choices: The valid names.
    """
    folded: dict[str, str] = {}
    for choice in choices:
        folded.setdefault(choice.lower(), choice)  # the first of names equal but for case
    close = difflib.get_close_matches(name.lower(), list(folded), n=1, cutoff=0.6)
    return f" (did you mean '{folded[close[0]]}'?)" if close else ""


class RunFailed(DfcoaError):
    """A run could not go on: a controller's bad command, or a state that left float range.

    ``dfcoa run`` prints it as ``run failed: ...`` (exit code 1); a sweep records
    the run as ``failed`` with this message.
    """


class ControllerError(RunFailed):
    """A controller returned a malformed or non-finite command (the run fails)."""
