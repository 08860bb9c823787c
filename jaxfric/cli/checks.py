"""Checks of a command's arguments and files that run before JAX is imported.

Everything a user can get wrong on the command line and that needs no model or
compiled program is checked here, in NumPy and the standard library only: the input
files (there, a file and not a folder, text, rectangular, numbers), the columns named
(in the header, no empty or NaN cell), model names and the report folder. A mistake is
one ``jaxfric: error:`` line a fraction of a second after the command starts, instead of
after JAX's import (several seconds on a loaded machine). What needs the models (the
parameters each model searches, the ranges a parameter accepts, the memory a model's
solver needs) is checked right after the import, still before any stage starts
([`jaxfric.cli.fitting.check_models`][jaxfric.cli.fitting.check_models], [`jaxfric.cli.fitting.check_memory`][jaxfric.cli.fitting.check_memory]).

The columns read here are kept on ``args`` (``args.columns``), so the data are read once.
"""

from __future__ import annotations

import os

from .errors import UserError

#: The models the commands accept (jaxfric.models.available(); a test keeps them equal,
#: here so that a misspelt name is refused without importing JAX).
MODEL_NAMES = ("elman", "elman_full", "lugre", "dahl", "coulomb", "stribeck", "gms", "cylinder", "greybox")


def check_model_names(names) -> list[str]:
    """Refuse a name that is not a model (one line naming the choices)."""
    for name in names:
        if name not in MODEL_NAMES:
            raise UserError(f"unknown model {name!r}; choose from {', '.join(MODEL_NAMES)}")
    return list(names)


def check_out_folder(path: str) -> None:
    """The report folder can be made (it is created only once the first fit is done)."""
    if os.path.exists(path) and not os.path.isdir(path):
        raise UserError(f"--out {path} exists and is not a folder")
    parent = os.path.dirname(os.path.abspath(path))
    while not os.path.exists(parent):
        parent = os.path.dirname(parent)
    target = path if os.path.isdir(path) else parent
    if not os.path.isdir(target) or not os.access(target, os.W_OK):
        raise UserError(f"cannot create the report folder {path}: {target} is not a writable folder")


def precheck(args) -> None:
    """Run the JAX-free checks of ``args.command`` (raises [`UserError`][jaxfric.cli.UserError])."""
    command = args.command
    if command in ("demo", "identify", "identify-motion"):
        check_model_names(args.models)
        check_out_folder(args.out)
    if command == "identify":
        from .data import identification_columns

        args.columns = {args.file: identification_columns(args, args.file)}
        for path in getattr(args, "valid", None) or []:
            args.columns[path] = identification_columns(args, path)
    elif command == "predict":
        from .data import prediction_columns

        if not os.path.exists(args.model_file):
            raise UserError(f"model file not found: {args.model_file}")
        if os.path.isdir(args.model_file):
            raise UserError(f"{args.model_file} is a folder, not a saved fit (.npz)")
        if args.out != "-" and os.path.isdir(args.out):
            raise UserError(f"--out {args.out} is a folder; give a file name, e.g. "
                            f"{os.path.join(args.out, 'predictions.csv')}")
        args.columns = {args.data: prediction_columns(args)}
    elif command == "identify-motion":
        path = args.file
        if not os.path.exists(path):
            raise UserError(f"file not found: {path}")
        if os.path.isdir(path):
            raise UserError(f"{path} is a folder, not a data file")
