// Typesets the maths that pymdownx.arithmatex (generic mode) leaves as \( ... \) and
// \[ ... \] inside .arithmatex elements. KaTeX is served with the site
// (docs/javascripts/katex/), so the equations render without a network connection.
// document$ is mkdocs-material's page observable: it fires on every page, including
// pages reached through instant navigation.
document$.subscribe(({ body }) => {
  for (const element of body.querySelectorAll(".arithmatex")) {
    renderMathInElement(element, {
      delimiters: [
        { left: "\\(", right: "\\)", display: false },
        { left: "\\[", right: "\\]", display: true },
      ],
      throwOnError: false,
    });
  }
});
