"""``jaxfric sweep DIR``: every (model, record, seed) identification, resumable ([`jaxfric.sweep`][jaxfric.sweeps.sweep]).

Each ``--data`` file is read with the columns and options of ``jaxfric identify``; each
``--model`` gets the solver ``jaxfric identify`` would give it (the same budget
options). ``DIR`` receives ``results.csv``, ``sweep.json`` and ``fits/<model>/<record>/
seed<k>.npz``; running the same command again finishes an interrupted sweep without
redoing the finished runs.
"""

from __future__ import annotations

import argparse
import re
from pathlib import Path

from .checks import MODEL_NAMES
from .errors import UserError
from .fitting import REFINE_CHOICES

EPILOG = """\
Runs identify once per (model, record, seed): one fit file per run under DIR/fits/, one
table DIR/results.csv. Interrupted (Ctrl-C, a killed job)? Run the same command again:
finished runs are read back, not recomputed.

Several processes: --process-index I --process-count N gives this process every N-th run
(e.g. a Slurm job array: --process-index $SLURM_ARRAY_TASK_ID); --distributed joins JAX's
distributed runtime (jax.distributed.initialize(), e.g. under srun) and takes the split
from it; the processes must share DIR. See docs/scale.md.

examples:
  jaxfric sweep runs/ --model lugre,dahl --data a.csv --data b.csv --keys 8 \\
      --velocity-col v --friction-col F --time-col t
  jaxfric sweep runs/ --model elman --data rec.csv --keys 0,3,7 --velocity-col 0 \\
      --friction-col 1 --dt 0.001 --quick
"""


def seeds(text: str):
    """``--keys``: a count K (seeds 0..K-1), a list ``0,3,7`` or a range ``10-19``."""
    text = text.strip()
    try:
        if re.fullmatch(r"\d+", text):
            k = int(text)
            if k < 1:
                raise ValueError
            return k
        if re.fullmatch(r"\d+-\d+", text):
            lo, hi = (int(t) for t in text.split("-"))
            if hi < lo:
                raise ValueError
            return list(range(lo, hi + 1))
        values = [int(t) for t in text.split(",") if t.strip()]
        if not values or min(values) < 0 or len(set(values)) != len(values):
            raise ValueError
        return values
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"expected a count K >= 1, a list of distinct seeds 0,3,7 or a range 10-19, got {text!r}") from None


def add_parser(sub, *, common, columns, formatter, positive_int, fraction, box_entry, model_list,
               solvers) -> None:
    """Register the ``sweep`` sub-command on ``sub`` (the CLI's subparsers)."""
    p = sub.add_parser("sweep", help="identify every model on every record for every seed, resumably",
                       description="Run identify for every (model, record, seed), write one fit file per "
                       "run and one results table, and resume an interrupted sweep.",
                       epilog=EPILOG, formatter_class=formatter)
    p.add_argument("dir", metavar="DIR", help="sweep folder (created; reused to resume)")
    p.add_argument("--data", action="append", required=True, metavar="FILE",
                   help="a recording (repeatable); all read with the same column options")
    p.add_argument("--keys", type=seeds, default=4, metavar="K|LIST|RANGE",
                   help="seeds: a count K (0..K-1), a list 0,3,7 or a range 10-19")
    columns(p)
    g = p.add_argument_group("identification")
    g.add_argument("--model", "--models", dest="models", type=model_list, default="lugre", metavar="NAMES",
                   help=f"comma-separated friction models ({', '.join(MODEL_NAMES)})")
    g.add_argument("--neurons", type=positive_int, default=None, help="hidden neurons of the Elman networks")
    g.add_argument("--solver", choices=solvers, default="mapso-nmds", help="optimiser")
    g.add_argument("--generations", type=positive_int, default=None, metavar="G", help="swarm generations")
    g.add_argument("--nm-evals", type=positive_int, default=None, metavar="N", help="Nelder-Mead evaluations")
    g.add_argument("--refine", choices=REFINE_CHOICES, default="none", help="gradient polish after the optimiser")
    g.add_argument("--paper", action="store_true", help="the paper's method exactly (MAPSO-NMDS, no gradient stage)")
    g.add_argument("--box", action="append", type=box_entry, default=None, metavar="NAME=LO,HI",
                   help="search range of a physical model's parameter in SI units (repeatable)")
    g.add_argument("--train-fraction", type=fraction, default=None, metavar="F",
                   help="leading fraction of each record used for estimation")
    g.add_argument("--quick", action="store_true", help="tiny budget: a smoke test in seconds, not a real fit")
    h = p.add_argument_group("processes")
    h.add_argument("--process-index", type=int, default=None, metavar="I", help="this process's share: runs I, I+N, ...")
    h.add_argument("--process-count", type=positive_int, default=None, metavar="N", help="number of processes sharing DIR")
    h.add_argument("--distributed", action="store_true",
                   help="call jax.distributed.initialize() (arguments from the cluster's environment, e.g. "
                   "Slurm) and split the runs over its processes")
    common(p)


def _record_labels(paths: list[str]) -> list[str]:
    labels = []
    for path in paths:
        base = re.sub(r"[^A-Za-z0-9_.+=-]", "_", Path(path).stem).lstrip("._-+=") or "record"
        label, n = base, 2
        while label in labels:
            label, n = f"{base}-{n}", n + 1
        labels.append(label)
    return labels


def cmd_sweep(args, argv) -> int:
    """Build the records and per-model options from the arguments and run [`jaxfric.sweep`][jaxfric.sweeps.sweep]."""
    del argv
    from jaxfric.identification import as_record
    from jaxfric.sweeps import sweep

    from .data import identification_data
    from .fitting import check_models
    from .spec import FitSpec

    if (args.process_index is None) != (args.process_count is None):
        raise UserError("give both --process-index and --process-count, or neither")
    if args.process_index is not None:
        if args.distributed:
            raise UserError("--distributed takes the split from JAX's runtime: leave out --process-index/--process-count")
        if not 0 <= args.process_index < args.process_count:
            raise UserError(f"--process-index must lie in 0..{args.process_count - 1}, got {args.process_index}")
    if args.distributed:
        import jax

        # before anything touches a JAX backend (the runtime must come first)
        jax.distributed.initialize()
    check_models(args.models, args.box)
    say = (lambda *_: None) if args.quiet else (lambda text: print(text, flush=True))
    records = {}
    for label, path in zip(_record_labels(args.data), args.data):
        data, _, notes = identification_data(argparse.Namespace(**{**vars(args), "file": path}))
        try:
            as_record(data)
        except ValueError as err:
            raise UserError(f"{path}: {err}") from None
        for note in notes:
            say(f"note: {path}: {note}")
        records[label] = data
    spec_args = argparse.Namespace(**{**vars(args), "seed": 0})
    models = {}
    for name in args.models:
        spec = FitSpec.from_args(name, spec_args)
        options = {k: v for k, v in spec.options().items() if v is not None or k == "model_options"}
        if spec.refine == "none":  # the sweep's "none": identify's own choice
            options.pop("refine")
        models[name] = (name, options)
    processes = ({} if args.process_index is None
                 else {"process_index": args.process_index, "process_count": args.process_count})
    result = sweep(models, records, args.keys, args.dir, progress=not args.quiet, **processes)
    say(f"{len(result.computed)} runs computed, {len(result.done)} found finished; "
        f"table: {result.table}")
    return 0
