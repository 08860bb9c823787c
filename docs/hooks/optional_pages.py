"""mkdocs hook: nav entries whose page does not exist yet are left out of the site.

The nav lists the guides other parts of the project write (``identify.md``, ``motion.md``,
``uncertainty.md``, ``solvers.md``, ``scale.md``); until a page exists its entry is dropped here, so the strict
build (``mkdocs build --strict``) stays an error for every other missing page or link.
"""

from __future__ import annotations

import os

OPTIONAL = {"identify.md", "motion.md", "uncertainty.md", "solvers.md", "scale.md"}


def _prune(items, docs_dir):
    out = []
    for item in items:
        if isinstance(item, dict):
            (title, value), = item.items()
            if isinstance(value, list):
                kept = _prune(value, docs_dir)
                if kept:
                    out.append({title: kept})
                continue
            if value in OPTIONAL and not os.path.isfile(os.path.join(docs_dir, value)):
                continue
        out.append(item)
    return out


def on_config(config, **kwargs):
    config["nav"] = _prune(config["nav"], config["docs_dir"])
    return config
