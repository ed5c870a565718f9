"""Griffe extension: Sphinx roles in docstrings become cross-references in the API pages.

The docstrings of ``dfcoa_opt`` and ``comparisons`` name other objects with Sphinx roles,
e.g. ``:class:`Observation``` or ``:func:`~dfcoa_opt.scenario.loader.load_scenario```.
mkdocstrings renders Markdown, where such a role would show as raw markup. Once a package
is loaded, this extension rewrites every role of its docstrings into a mkdocs-autorefs
cross-reference:

- the target is resolved the way Python would see the name from the documented object:
  its own members, then its parents' (a class, its module, with the module's imports),
  so ``Observation`` in ``dfcoa_opt.api`` is ``dfcoa_opt.control.base.Observation``; a
  dotted target (``dfcoa_opt.scenario.loader.load_scenario``, ``Grid.inflate``) resolves its
  first name the same way, and a re-export is followed to the object it names;
- the reference is an *optional* autoref: a link where the target is rendered somewhere on
  the site, the plain code name where it is not (a private helper, the standard library);
- a target that cannot be resolved at all renders as the plain code name.

The text follows Sphinx: ``~`` keeps the last name only, ``title <target>`` shows the
title, ``!`` never links, and functions and methods get ``()``. Roles inside fenced code
blocks of a docstring are left as they are. Enabled in ``mkdocs.yml`` under the python
handler's ``extensions``.
"""

from __future__ import annotations

import html
import re
from collections.abc import Iterator
from typing import Any

from griffe import (
    AliasResolutionError,
    CyclicAliasError,
    Extension,
    GriffeLoader,
    Module,
    NameResolutionError,
    Object,
)

ROLE = re.compile(
    r"(?<![\w`]):(?:py:)?(?P<role>class|func|meth|mod|attr|data|exc|obj|const|type|any)"
    r":`(?P<body>[^`]+)`"
)
"""A Sphinx role of the Python domain, e.g. ``:func:`~pkg.mod.name```."""

_FENCE = re.compile(r"^\s*(```|~~~)")
_CALLABLE_ROLES = {"func", "meth"}
_LOOKUP_ERRORS = (AliasResolutionError, CyclicAliasError, KeyError, NameResolutionError)


def _walk(obj: Object) -> Iterator[Object]:
    """Yield ``obj`` and every object defined under it (not the aliases it imports)."""
    yield obj
    for member in obj.members.values():
        if not member.is_alias:
            yield from _walk(member)  # type: ignore[arg-type]


def _canonical(path: str, loader: GriffeLoader) -> str:
    """The path of the object that ``path`` finally names (following re-exports)."""
    try:
        return loader.modules_collection[path].canonical_path
    except _LOOKUP_ERRORS:
        return path


def resolve_target(obj: Object, target: str, loader: GriffeLoader) -> str | None:
    """The full path a role's target names when read from ``obj``'s docstring.

    Args:
        obj: The object whose docstring holds the role.
        target: The role's target, without ``~``, ``!`` or a title.
        loader: The loader, whose collection holds the loaded packages.

    Returns:
        The full dotted path, or None when the name is not known in ``obj``'s scope and
        is not a dotted path from a top-level package.
    """
    target = target.removesuffix("()").lstrip(".")
    if not target or not all(part.isidentifier() for part in target.split(".")):
        return None
    first, _, rest = target.partition(".")
    try:
        path = obj.resolve(first)
    except _LOOKUP_ERRORS:
        if not rest:
            return None
        path = first  # an absolute path such as dfcoa_opt.scenario.loader.load_scenario
    full = f"{path}.{rest}" if rest else path
    return _canonical(full, loader)


def _display(role: str, body: str) -> tuple[str, str, bool]:
    """Split a role's body into (text shown, target, whether it may link)."""
    body = " ".join(body.split())
    link = not body.startswith("!")
    body = body.lstrip("!")
    titled = re.fullmatch(r"(?P<title>.+?)\s*<(?P<target>[^<>]+)>", body)
    if titled:
        return titled["title"], titled["target"].lstrip("~"), link
    target = body.lstrip("~")
    text = target.rsplit(".", 1)[-1] if body.startswith("~") else target
    if role in _CALLABLE_ROLES and not text.endswith(")"):
        text += "()"
    return text, target, link


def convert_roles(text: str, obj: Object, loader: GriffeLoader) -> str:
    """Rewrite the Sphinx roles of one docstring as autorefs cross-references.

    Args:
        text: The docstring.
        obj: The object it documents (the scope that short names are read in).
        loader: The loader, whose collection holds the loaded packages.

    Returns:
        The docstring with every role outside fenced code replaced: by
        ``<autoref identifier="path" optional>`name`</autoref>`` when its target resolves,
        else by ```name```.
    """

    def replace(match: re.Match[str]) -> str:
        shown, target, link = _display(match["role"], match["body"])
        code = f"`{shown}`"
        path = resolve_target(obj, target, loader) if link else None
        if path is None:
            return code
        return f'<autoref identifier="{html.escape(path)}" optional>{code}</autoref>'

    out: list[str] = []
    in_fence = False
    for line in text.splitlines(keepends=True):
        if _FENCE.match(line):
            in_fence = not in_fence
        out.append(line if in_fence else ROLE.sub(replace, line))
    return "".join(out)


class SphinxRoles(Extension):
    """Convert the Sphinx roles of a loaded package's docstrings into cross-references."""

    def on_package(self, *, pkg: Module, loader: GriffeLoader, **kwargs: Any) -> None:
        """Rewrite the docstrings of every object of the package.

        Args:
            pkg: The package, completely loaded.
            loader: The loader in use.
            **kwargs: Other arguments of the event (unused).
        """
        for obj in _walk(pkg):
            docstring = obj.docstring
            if docstring is None or ":`" not in docstring.value:
                continue
            docstring.value = convert_roles(docstring.value, obj, loader)
            docstring.__dict__.pop("parsed", None)  # parse the new text if parsed before
