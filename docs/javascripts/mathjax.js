// MathJax 3 configuration, read by docs/assets/mathjax/tex-svg.js (loaded after this file).
// pymdownx.arithmatex (generic mode) writes $...$ as <span class="arithmatex">\(...\)</span>
// and $$...$$ as <div class="arithmatex">\[...\]</div>; only those elements are typeset.
window.MathJax = {
  tex: {
    inlineMath: [["\\(", "\\)"]],
    displayMath: [["\\[", "\\]"]],
    processEscapes: true,
    processEnvironments: true,
    tags: "none"
  },
  options: {
    ignoreHtmlClass: ".*|",
    processHtmlClass: "arithmatex"
  },
  svg: {
    fontCache: "global"
  }
};

// With Material's instant navigation a page is swapped in without a reload: typeset it again.
if (typeof document$ !== "undefined") {
  document$.subscribe(function () {
    if (window.MathJax && MathJax.typesetPromise) {
      MathJax.startup.output.clearCache();
      MathJax.typesetClear();
      MathJax.texReset();
      MathJax.typesetPromise();
    }
  });
}
