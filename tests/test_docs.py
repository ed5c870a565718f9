"""The documentation site builds with --strict and works opened from disk.

One build (``mkdocs build --strict``) serves every test of the site: the pytest-xdist
workers share it through a lock file. The Markdown checks read the sources only.
"""

from __future__ import annotations

import fcntl
import os
import re
import subprocess
import sys
from html.parser import HTMLParser
from pathlib import Path
from urllib.parse import unquote, urlsplit

import markdown
import pytest

ROOT = Path(__file__).resolve().parents[1]
MARKDOWN = [*sorted((ROOT / "docs").rglob("*.md")), ROOT / "README.md"]
# a Sphinx role left in the HTML: Markdown makes its backticks a <code> element
ROLE = re.compile(r":(?:class|func|meth|mod|attr|data|exc):(?:`|<code>)")


@pytest.fixture(scope="module")
def site(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The built site: built once, by whichever test worker gets here first."""
    shared = tmp_path_factory.getbasetemp()
    if os.environ.get("PYTEST_XDIST_WORKER"):
        shared = shared.parent  # the same folder for every worker of this run
    out, done = shared / "docs-site", shared / "docs-site.result"
    with open(shared / "docs-site.lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        if not done.exists():
            env = {**os.environ, "NO_MKDOCS_2_WARNING": "1"}
            proc = subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict",
                                   "--site-dir", str(out)], cwd=ROOT, capture_output=True,
                                  text=True, timeout=900, env=env)
            done.write_text(f"{proc.returncode}\n{proc.stderr[-3000:]}")
    code, _, stderr = done.read_text().partition("\n")
    assert code == "0", stderr
    return out


def _pages(site: Path) -> list[Path]:
    return sorted(site.rglob("*.html"))


def test_the_site_builds_strict(site: Path) -> None:
    # the generated key reference, the rendered tutorial and the API reference are pages
    assert "comms.<wbr>latency" in (site / "scenario-keys.html").read_text()
    assert "capped_goto" in (site / "tutorial.html").read_text()
    api = (site / "api" / "controllers.html").read_text()
    assert "Nmpc" in api and "VFHParams" in api
    params = (site / "controller-params.html").read_text()
    assert "controllers.<wbr>dfcoa.<wbr>compensate_tracking_offset" in params
    assert "controllers.<wbr>cbf.<wbr>solver" in params
    # the build's own Python (the hooks, the griffe extension) is not published
    assert not list(site.rglob("*.py"))


class _Links(HTMLParser):
    """The href and src attributes of a page (links, stylesheets, scripts, images)."""

    def __init__(self) -> None:
        super().__init__()
        self.urls: list[tuple[str, str, str]] = []  # (tag, url, rel)

    def handle_starttag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
        found = dict(attrs)
        for name in ("href", "src"):
            if name in found:
                self.urls.append((tag, str(found[name] or ""), str(found.get("rel") or "")))


def _links(page: Path) -> list[tuple[str, str, str]]:
    parser = _Links()
    parser.feed(page.read_text(encoding="utf-8"))
    return parser.urls


def test_every_relative_link_of_the_site_is_a_file(site: Path) -> None:
    # opened from disk (file://) there is no server to map a folder to its index.html
    broken = []
    for page in _pages(site):
        if page.name == "404.html" and page.parent == site:
            continue  # a web server's error page: its links start at the server's root
        for tag, url, _ in _links(page):
            parts = urlsplit(url)
            if not url and tag in ("script", "img", "iframe"):
                broken.append(f"{page.relative_to(site)}: <{tag}> with an empty src")
            if parts.scheme or parts.netloc or not parts.path:
                continue  # another site, mailto:, or an anchor on this page
            target = (page.parent / unquote(parts.path)).resolve()
            if not target.is_file():
                broken.append(f"{page.relative_to(site)}: <{tag}> {url}")
    assert not broken, "\n".join(broken[:30])


def test_nothing_is_loaded_from_the_network(site: Path) -> None:
    remote = []
    for page in _pages(site):
        for tag, url, rel in _links(page):
            loaded = tag in ("script", "img", "iframe") or (
                tag == "link" and rel in ("stylesheet", "preconnect", "preload", "icon"))
            if loaded and urlsplit(url).netloc:  # http://, https:// or //host (not data:)
                remote.append(f"{page.relative_to(site)}: <{tag}> {url[:120]}")
    assert not remote, "\n".join(remote[:30])


def test_search_works_offline(site: Path) -> None:
    index = site / "search" / "search_index.js"
    assert index.read_text(encoding="utf-8").startswith("var __index = {")
    # the Web Worker shim that file:// needs comes from the site itself
    home = (site / "index.html").read_text()
    assert '<script src="assets/iframe-worker/shim.js"></script>' in home
    assert (site / "assets" / "iframe-worker" / "shim.js").is_file()


def test_the_api_pages_have_no_raw_sphinx_roles(site: Path) -> None:
    pages = sorted((site / "api").glob("*.html"))
    assert pages
    raw = [f"{p.name}: {m[0]}" for p in pages for m in ROLE.finditer(p.read_text())]
    assert not raw, raw[:20]
    # the roles became cross-references: links between the API pages
    control = (site / "api" / "control.html").read_text()
    assert re.search(r'<a class="autorefs autorefs-internal"[^>]*'
                     r'href="sim\.html#dfcoa_opt\.sim\.batch\.BatchSimulator"><code>', control)
    text = {p.resolve(): p.read_text() for p in _pages(site)}
    pages = [p.resolve() for p in pages]
    links = [(p, href) for p in pages for href in re.findall(
        r'<a class="autorefs autorefs-internal"[^>]*href="([^"]+)"><code>', text[p])]
    assert len(links) > 80
    for page, href in links:  # each lands on its object's heading
        path, _, anchor = href.partition("#")
        assert f'id="{anchor}"' in text[(page.parent / path).resolve() if path else page], href
    # a role left as plain code names an object that no page documents
    anchors = {a for t in text.values() for a in re.findall(r'\bid="([^"]+)"', t)}
    plain = {i for p in pages for i in re.findall(r'<span title="([^"]+)"><code>', text[p])}
    assert plain and not plain & anchors, sorted(plain & anchors)


def test_maths_is_typeset_by_the_sites_own_mathjax(site: Path) -> None:
    page = site / "methods" / "formation_law.html"
    text = page.read_text()
    assert '<div class="arithmatex">\\[' in text  # display maths, $$ ... $$
    assert '<span class="arithmatex">\\(' in text  # inline maths, $ ... $
    scripts = [url for tag, url, _ in _links(page) if tag == "script"]
    assert "../javascripts/mathjax.js" in scripts and "../assets/mathjax/tex-svg.js" in scripts
    assert (page.parent / "../assets/mathjax/tex-svg.js").resolve().stat().st_size > 1e6
    # no equation is left as an ASCII code block on the method pages
    for method in sorted((site / "methods").glob("*.html")):
        for block in re.findall(r"<pre><span></span><code>(.*?)</code></pre>",
                                method.read_text(), flags=re.S):
            assert not re.search(r"[=≤≥] .*[Σ√∑θω]", block), (method.name, block[:200])


def test_long_keys_wrap_only_at_dots(site: Path) -> None:
    keys = (site / "scenario-keys.html").read_text()
    assert '<code class="dotted-key">world.<wbr>clutter.<wbr>density</code>' in keys
    assert "<td><code>world." not in keys  # every key of the table is wrapped so
    assert '<link rel="stylesheet" href="stylesheets/extra.css">' in keys
    css = (site / "stylesheets" / "extra.css").read_text()
    rule = css[css.index(".md-typeset code.dotted-key"):]
    assert "word-break: normal" in rule and "overflow-wrap: normal" in rule


# --- the Markdown sources ---------------------------------------------------------------

LIST_ITEM = re.compile(r"^\s*(?:[-*+]|\d+\.)\s+\S")  # Python-Markdown's markers
FENCE = re.compile(r"^\s*(?:```|~~~)")
STAR_NAME = re.compile(r"\b(?:A|VFH)\*")


def _prose(text: str) -> list[tuple[int, str | None]]:
    """(line number, line) with None for the lines of code fences and $$ blocks."""
    out: list[tuple[int, str | None]] = []
    fence = maths = False
    for number, line in enumerate(text.splitlines(), 1):
        stripped = line.strip()
        if FENCE.match(line):
            fence = not fence
            line = None
        elif not fence and stripped.startswith("$$"):
            if not (len(stripped) > 2 and stripped.endswith("$$")):  # not a one-line block
                maths = not maths
            line = None
        out.append((number, None if fence or maths else line))
    return out


def glued_lists(text: str) -> list[int]:
    """Lines that start a list right under a paragraph line (Python-Markdown joins them)."""
    bad, block = [], []
    for number, line in _prose(text):
        if line is None or not line.strip():
            block = []
            continue
        if (LIST_ITEM.match(line) and block and not any(LIST_ITEM.match(b) for b in block)
                and not block[-1].lstrip().startswith("#")):
            bad.append(number)
        block.append(line)
    return bad


def misindented(text: str) -> list[int]:
    """Lines whose indent Python-Markdown reads otherwise than a reader would.

    A nested list item needs 4 spaces per level (at 2 it becomes a sibling of its parent),
    and a paragraph after a blank line inside a list needs 4 too (with fewer it leaves the
    list, and the next item runs into it).
    """
    bad, after_blank = [], True
    for number, line in _prose(text):
        if line is not None and not line.strip():
            after_blank = True
            continue
        indent = len(line) - len(line.lstrip(" ")) if line else 0
        if line and (LIST_ITEM.match(line) and indent % 4 or after_blank and 0 < indent < 4):
            bad.append(number)
        after_blank = False
    return bad


def unescaped_stars(text: str) -> list[int]:
    """Lines with an ``A*`` or ``VFH*`` outside code, whose * would start emphasis."""
    bad = []
    for number, line in _prose(text):
        if line is None:
            continue
        bare = re.sub(r"\$[^$]+\$", "", re.sub(r"(`+).*?\1", "", line))
        if STAR_NAME.search(bare):
            bad.append(number)
    return bad


def test_the_checks_of_the_markdown_sources_catch_what_they_look_for() -> None:
    assert glued_lists("Text:\n- a\n- b\n") == [2]
    assert glued_lists("Text:\n\n- a\n  more\n- b\n\n## H\n- c\n```\nx\n- y\n```\n") == []
    assert unescaped_stars("improved A* and VFH\\*\n`A*` $A*$\n") == [1]
    assert misindented("- a\n  - b\n    - c\n\n  more of a\n\n    more of a\n") == [2, 5]


@pytest.mark.parametrize("path", MARKDOWN, ids=lambda p: str(p.relative_to(ROOT)))
def test_markdown_lists_are_written_as_python_markdown_reads_them(path: Path) -> None:
    text = path.read_text(encoding="utf-8")
    where = [f"{path.relative_to(ROOT)}:{n}" for n in glued_lists(text)]
    assert not where, "a list needs a blank line before it:\n" + "\n".join(where)
    where = [f"{path.relative_to(ROOT)}:{n}" for n in misindented(text)]
    assert not where, "indent nested list content by 4 spaces a level:\n" + "\n".join(where)
    stars = [f"{path.relative_to(ROOT)}:{n}" for n in unescaped_stars(text)]
    assert not stars, "write A\\* and VFH\\* outside code:\n" + "\n".join(stars)


@pytest.mark.parametrize("path", MARKDOWN, ids=lambda p: str(p.relative_to(ROOT)))
def test_no_list_runs_into_a_paragraph_when_rendered(path: Path) -> None:
    # rendered as the site renders it: a list marker left inside a paragraph or an item
    # means the list ran together with the text above it
    html = markdown.markdown(path.read_text(encoding="utf-8"),
                             extensions=["tables", "admonition", "toc", "pymdownx.highlight",
                                         "pymdownx.superfences", "pymdownx.arithmatex"])
    html = re.sub(r"<pre.*?</pre>|<div class=\"arithmatex\">.*?</div>", "", html, flags=re.S)
    texts = [m[2] for m in re.finditer(r"<(p|li)>(.*?)</\1>", html, flags=re.S)]
    marker = re.compile(r"\n[ \t]*(?:[-*+]|\d+\.)[ \t]+\S[^\n]*")
    glued = [m[0].strip()[:80] for text in texts for m in marker.finditer(text)]
    assert not glued, f"{path.relative_to(ROOT)}:\n" + "\n".join(glued)


# --- formulas and links of the method notes and the reference pages ------------------

# These pages write their formulas as LaTeX for the site's MathJax ($...$ inline, $$...$$
# display: pymdownx.arithmatex) and their links as the target page's title.
MATHS_PAGES = [*sorted((ROOT / "docs" / "methods").glob("*.md")),
               *(ROOT / "docs" / f"{name}.md" for name in (
                   "reproduction", "metrics", "comms", "envs", "policies", "robots",
                   "heldout", "bench_scenarios"))]
CODE_SPAN = re.compile(r"(?<!`)(`+)(?!`)(.+?)(?<!`)\1(?!`)", flags=re.S)
TEX_MARK = re.compile(r"\^|_\{|\|\||sqrt\(|argmin|sum_|[‖√Σ∑²³]")
RELATION = re.compile(r"[=<>≤≥≠]")
CODE_LIKE = re.compile(
    r""""|'\w[^']*'|\\|==|!=|[-+*/]=|\*\*"""       # a string, an escape, a Python operator
    r"|^(?:dfcoa|python|pip|make)\b"               # a command line
    r"|^[A-Za-z_]\w*(?:\.\w+|\[[^\]]*\])+\s*="     # a dotted key, attribute or item, assigned
    r"|\w\(.*\b\w+="                               # a call with a keyword argument
    r"|^[A-Za-z_][\w.]*\s*=\s*(?:[-+]?[\d.]+(?:e[-+]?\d+)?(?:\s+\S+)?|true|false"
    r"|\[[^\]]*\])$")                              # a key set to a literal (with a unit)
FILE_NAME_LINK = re.compile(r"(?<!!)\[\s*(`?)([\w./-]+\.md(?:#[\w-]*)?)\1\s*\]\(")


def _prose_text(text: str) -> str:
    """The text with the lines of code fences and $$ blocks blanked (line numbers kept)."""
    return "\n".join(line or "" for _, line in _prose(text))


def pseudo_tex(text: str) -> list[tuple[int, str]]:
    """(line, span) of the code spans outside fences that are formulas in pseudo-TeX.

    A code span is a formula when it holds a TeX-like mark (``^``, ``_{``, ``||``,
    ``sqrt(``, ``argmin``, ``sum_``, or one of ‖ √ Σ ∑ ² ³) and a relation (``=``, ``<``,
    ``>``, ≤, ≥, ≠), and is not code: no string (a ``"``, or ``'`` before a word), no
    backslash, no Python operator (``==``, ``!=``, ``+=`` and the like, ``**``), not a
    command line (``dfcoa``, ``python``, ``pip``, ``make``), not a dotted key, attribute
    or item being assigned (``world.clutter.density = …``, ``obs.slot[i] = …``), not a call
    with a keyword argument (``param(…, tune=(…))``), and not a key set to a literal
    (``a_max = 1000 m/s²``, ``alpha = 0``, ``particle_limits = [500, 5000]``).
    """
    prose = _prose_text(text)
    found = []
    for match in CODE_SPAN.finditer(prose):
        span = " ".join(match[2].split())
        if TEX_MARK.search(span) and RELATION.search(span) and not CODE_LIKE.search(span):
            found.append((prose.count("\n", 0, match.start()) + 1, span))
    return found


def file_name_links(text: str) -> list[tuple[int, str]]:
    """(line, text) of the Markdown links outside code whose text is a bare ``*.md`` name."""
    found = []
    for number, line in _prose(text):
        if line is not None:
            bare = re.sub(r"(`+).*?\1", lambda m: m[0] if m[0].endswith(".md`") else "", line)
            found += [(number, m[2]) for m in FILE_NAME_LINK.finditer(bare)]
    return found


def test_the_formula_and_link_checks_catch_what_they_look_for() -> None:
    formulas = ("`V_IVO = argmin_{IVOA+} ||v − v_pref||` and\n"
                "`p = z_hit exp(-d^2 / (2 sigma^2)) + z_rand / z_max`, `w = 1/d_i^2`,\n"
                "`E_s = sqrt((Σ_i u_x)² + (Σ_i u_y)²)`, `‖v(0)‖ > v_max`\n")
    assert [n for n, _ in pseudo_tex(formulas)] == [1, 2, 2, 3, 3]
    code = ("`world.clutter.density = 0.2`, `dfcoa bench x.toml --set 'a=1'`, `y == x**2`,\n"
            "`a_max = 1000 m/s²`, `obs.slot[i] = x_L + R(θ)^2`, `param(1.0, tune=(0.2, 5.0))`,\n"
            "`formation_centroid_error`, `E_c`, $E_c = \\lVert X_c - X_c^* \\rVert$\n"
            "```\n`E = ||x||`\n```\n")
    assert pseudo_tex(code) == []
    links = ("[orca_ivo.md](orca_ivo.md), [`x.md`](x.md) and\n"
             "[docs/metrics.md](metrics.md#risk), [../reproduction.md](../reproduction.md)\n"
             "[Metrics](metrics.md), `[a.md](a.md)`, ![a.md](a.png), [the file a.md](a.md)\n")
    assert file_name_links(links) == [(1, "orca_ivo.md"), (1, "x.md"), (2, "docs/metrics.md"),
                                      (2, "../reproduction.md")]


@pytest.mark.parametrize("path", MATHS_PAGES, ids=lambda p: str(p.relative_to(ROOT)))
def test_formulas_are_latex_not_code_font_pseudo_tex(path: Path) -> None:
    found = [f"{path.relative_to(ROOT)}:{n}: `{span}`" for n, span in
             pseudo_tex(path.read_text(encoding="utf-8"))]
    assert not found, ("write these formulas as LaTeX maths, $...$ or $$...$$ "
                       "(in a table, \\lvert/\\lVert for |):\n" + "\n".join(found))


@pytest.mark.parametrize("path", MATHS_PAGES, ids=lambda p: str(p.relative_to(ROOT)))
def test_links_read_as_page_titles_not_file_names(path: Path) -> None:
    found = [f"{path.relative_to(ROOT)}:{n}: [{name}](…)" for n, name in
             file_name_links(path.read_text(encoding="utf-8"))]
    assert not found, "let each link read as its page's title:\n" + "\n".join(found)


def test_the_scenario_table_is_the_committed_comparison() -> None:
    """docs/bench_scenarios.md shows the successes of paper_figures/comparison/runs.csv."""
    from dfcoa_opt.bench.report.tables import success_matrix
    from dfcoa_opt.bench.results.published import read_runs

    rows, _ = read_runs(ROOT / "paper_figures" / "comparison" / "runs.csv")
    text = (ROOT / "docs" / "bench_scenarios.md").read_text(encoding="utf-8")
    block = re.search(r"<!-- success-by-scenario -->\n(.*?)\n<!-- /success-by-scenario -->",
                      text, re.S)
    assert block, "docs/bench_scenarios.md: no <!-- success-by-scenario --> block"
    assert block.group(1) + "\n" == success_matrix(rows), (
        "copy the table of paper_figures/comparison/success_by_scenario.md into the block")
