"""mkdocs hook: pages generated from the code, so they cannot drift from it.

- ``scenario-keys.md``: the scenario key reference (``scenarios/README.md``,
  made by ``dfcoa schema``);
- ``controller-params.md``: every registered controller's and filter's
  ``Params`` (the ``[controllers.<id>]`` keys), from their field metadata,
  with the ranges ``dfcoa tune`` searches;
- ``world-families.md``: every world family's options (``[world.generate.options]``).

It also lets a dotted key of these pages' tables wrap only at its dots, and drops the
MathJax 2 loader that nbconvert puts in the rendered notebook (the site serves its own
MathJax, docs/assets/mathjax/).
"""

from __future__ import annotations

import html
import re
from pathlib import Path

from mkdocs.structure.files import File

ROOT = Path(__file__).resolve().parents[1]


def _params_page() -> str:
    import dfcoa_opt  # noqa: F401 - first: pins numpy's SIMD dispatch
    from dfcoa_opt.control import registry
    from dfcoa_opt.core.params import describe, tunables

    out = ["# Controller parameters", "",
           "Every registered controller's and safety filter's parameters: the keys of a "
           "scenario's `[controllers.<id>]` table (a filter's under its own id, e.g. "
           "`[controllers.cbf]` for `goto_slot+cbf`). A bad key or value is a one-line "
           "error naming it. Every number lies within +-1e9, and a key that must be "
           "positive (`> 0`) is at least 1e-9. Generated from the code by the "
           "documentation build.", ""]
    tables = [(cid, registry.controller_class(cid)) for cid in registry.available()]
    # a filter's class: the second of the classes behind "goto_slot+<filter>"
    tables += [(fid, registry.component_classes(f"goto_slot+{fid}")[1])
               for fid in registry.available_filters()]
    for cid, cls in tables:
        rows = describe(cls.Params, f"controllers.{cid}")
        out += [f"## `{cid}`", ""]
        if not rows:
            out += ["No parameters.", ""]
            continue
        out += ["| key | type | default | unit | meaning |", "|---|---|---|---|---|"]
        out += [f"| `{k}` | {t} | `{d}` | {u} | {doc} |" for k, t, d, u, doc in rows]
        out.append("")
        tuned = tunables(cls.Params)
        if tuned:
            out += ["Searched by `dfcoa tune` (docs: [held-out benchmark](heldout.md)): "
                    + "; ".join(_range(t) for t in tuned) + ".", ""]
    return "\n".join(out)


def _range(t) -> str:  # noqa: ANN001 - a dfcoa_opt.core.params.Tunable
    if t.kind == "bool":
        return f"`{t.key}` false or true"
    return f"`{t.key}` [{t.low:g}, {t.high:g}]" + (" (log)" if t.scale == "log" else "")


def _families_page() -> str:
    import dfcoa_opt  # noqa: F401 - first: pins numpy's SIMD dispatch
    from dfcoa_opt.core.params import describe
    from dfcoa_opt.world import generate

    out = ["# World families", "",
           "The options of each family of generated worlds: the keys of a scenario's "
           "`[world.generate.options]` table, with `[world.generate] family = \"<name>\"` "
           "([held-out benchmark](heldout.md)). A range `[low, high]` is drawn anew for every "
           "world. Generated from the code by the documentation build.", ""]
    for name in generate.family_names():
        cls = generate.family_params(name)
        module = __import__(f"dfcoa_opt.world.generate.{name}", fromlist=["x"])
        out += [f"## `{name}`", "", " ".join((module.__doc__ or "").split("\n\n")[1].split()),
                "", "| key | type | default | unit | meaning |", "|---|---|---|---|---|"]
        out += [f"| `{k}` | {t} | `{d}` | {u} | {doc} |"
                for k, t, d, u, doc in describe(cls, "world.generate.options")]
        out.append("")
    return "\n".join(out)


def on_files(files, config):  # noqa: ANN001, ANN201 - mkdocs hook signature
    """Add the generated pages to the site."""
    text = (ROOT / "scenarios" / "README.md").read_text(encoding="utf-8")
    files.append(File.generated(config, "scenario-keys.md", content=text))
    files.append(File.generated(config, "controller-params.md", content=_params_page()))
    files.append(File.generated(config, "world-families.md", content=_families_page()))
    return files


# the first cell of a table row when it is a dotted key (`world.clutter.density`), not a
# number such as `10.0`
_KEY_CELL = re.compile(r"(<tr>\s*<td>)<code>([A-Za-z_][^<\s]*\.[A-Za-z_][^<\s]*)</code>")
_KEY_PAGES = {"scenario-keys.md", "controller-params.md", "world-families.md"}
# nbconvert's template loads MathJax 2 (from a CDN, or from mkdocs-jupyter's empty
# custom_mathjax_url) and configures it in a script block
_NOTEBOOK_MATHJAX = re.compile(
    r'<!-- Load mathjax -->\s*<script src="[^"]*">\s*</script>'
    r'|<script type="text/x-mathjax-config">.*?</script>', re.DOTALL)


def _break_at_dots(match: re.Match[str]) -> str:
    key = html.unescape(match[2])
    wrapped = ".<wbr>".join(html.escape(part) for part in key.split("."))
    return f'{match[1]}<code class="dotted-key">{wrapped}</code>'


def on_page_content(html_text, page, config, files):  # noqa: ANN001, ANN201 - mkdocs hook
    """Put a line-break opportunity after each dot of the key column of the key tables."""
    if page.file.src_uri in _KEY_PAGES:
        return _KEY_CELL.sub(_break_at_dots, html_text)
    return html_text


def on_post_page(output, page, config):  # noqa: ANN001, ANN201 - mkdocs hook signature
    """Drop the MathJax 2 that nbconvert adds to the notebook's page (it has no maths)."""
    if page.file.src_uri.endswith(".ipynb"):
        return _NOTEBOOK_MATHJAX.sub("", output)
    return output
