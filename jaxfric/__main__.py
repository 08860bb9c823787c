"""``python -m jaxfric ...`` is the ``jaxfric`` command line."""

from jaxfric.cli import main

if __name__ == "__main__":
    raise SystemExit(main())
