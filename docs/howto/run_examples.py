"""Run the code of the how-to pages and write what it prints, and the figures it saves, into them.

    python docs/howto/run_examples.py                       # every page of docs/howto/
    JAXFRIC_DATA=/path/to/data python docs/howto/run_examples.py docs/howto/motion.md

Each page's ```python blocks run in order, in one namespace per page, in a temporary
folder (the page's code is a script a reader can paste). After each block that prints
something, the page gets (or has replaced) an output block between ``<!-- output -->``
and ``<!-- /output -->``; warnings raised by the block are shown there as a terminal
shows them. PNG files the code saves are copied to ``docs/howto/figures/``, where the
pages' ``![...](figures/NAME.png)`` lines find them. A block whose first line is
``# not run`` is shown but not run (e.g. it needs a file that is not shipped).

The pages that read real data (``motion.md``) need the EMPS recording: set
``JAXFRIC_DATA`` to a folder holding ``emps/DATA_EMPS.mat``, or let
``jaxfric.datasets`` download it.
"""

from __future__ import annotations

import contextlib
import io
import os
import re
import shutil
import sys
import tempfile
import time
import traceback
import warnings
from pathlib import Path

HERE = Path(__file__).resolve().parent
FIGURES = HERE / "figures"
BLOCK = re.compile(r"^```python\n(.*?)^```\n(?:\n?<!-- output -->\n.*?<!-- /output -->\n)?", re.S | re.M)


def _output_block(text: str) -> str:
    return f"\n<!-- output -->\n```text title=\"Output\"\n{text.rstrip()}\n```\n<!-- /output -->\n"


def run_page(page: Path) -> None:
    source = page.read_text(encoding="utf-8")
    namespace: dict = {"__name__": "__main__"}
    pieces, pos = [], 0
    start = time.perf_counter()
    old_cwd = os.getcwd()
    with tempfile.TemporaryDirectory() as work:
        os.chdir(work)
        try:
            for m in BLOCK.finditer(source):
                code = m.group(1)
                pieces.append(source[pos:m.start()])
                pieces.append(f"```python\n{code}```\n")
                pos = m.end()
                if code.startswith("# not run"):
                    continue
                before = set(Path(work).glob("*.png"))
                out = io.StringIO()
                with warnings.catch_warnings(record=True) as caught, contextlib.redirect_stdout(out):
                    warnings.simplefilter("always")
                    try:
                        exec(compile(code, f"{page.name}", "exec"), namespace)
                    except Exception:
                        sys.stderr.write(out.getvalue())
                        traceback.print_exc()
                        raise SystemExit(f"{page}: a block failed; the page is left as it was")
                text = out.getvalue()
                seen = set()
                for w in caught:
                    line = f"{w.category.__name__}: {w.message}"
                    if line not in seen:
                        seen.add(line)
                        text += line + "\n"
                if text.strip():
                    pieces.append(_output_block(text))
                for png in sorted(set(Path(work).glob("*.png")) - before):
                    FIGURES.mkdir(exist_ok=True)
                    shutil.copyfile(png, FIGURES / png.name)
                    print(f"  figure {FIGURES.relative_to(HERE.parents[1]) / png.name}")
        finally:
            os.chdir(old_cwd)
    pieces.append(source[pos:])
    page.write_text("".join(pieces), encoding="utf-8")
    print(f"{page.relative_to(HERE.parents[1])}: {time.perf_counter() - start:.0f} s")


def main(argv: list[str]) -> None:
    import matplotlib

    matplotlib.use("Agg")
    pages = [Path(p).resolve() for p in argv] or sorted(HERE.glob("*.md"))
    for page in pages:
        run_page(page)


if __name__ == "__main__":
    main(sys.argv[1:])
