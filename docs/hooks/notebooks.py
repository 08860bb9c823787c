"""mkdocs hook: the tutorials are the committed notebooks in ``notebooks/``.

The four notebooks (``notebooks/0N_*.ipynb``, built from their jupytext sources
``notebooks/0N_*.py``) live outside ``docs/``; this hook adds each one to the site under
the same path (``notebooks/0N_*.ipynb``), so mkdocs-jupyter renders it as it is committed,
without executing it. It runs before mkdocs-jupyter looks at the files (a higher priority).
"""

from __future__ import annotations

from pathlib import Path

from mkdocs.plugins import event_priority
from mkdocs.structure.files import File

ROOT = Path(__file__).resolve().parents[2]


@event_priority(100)
def on_files(files, config, **kwargs):
    for path in sorted((ROOT / "notebooks").glob("0*.ipynb")):
        files.append(File(f"notebooks/{path.name}", src_dir=str(ROOT), dest_dir=config["site_dir"],
                          use_directory_urls=config["use_directory_urls"]))
    return files
