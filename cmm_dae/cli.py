"""Command line interface ``cmm-dae``.

Commands: ``run``, ``iterate``, ``compare``, ``events``, ``structure``, ``animate``, ``plot``,
``sweep``, ``sensitivities``, ``design``, ``bench``, ``examples``, ``schema``. A model is a
TOML file or the name of a shipped example (``cmm-dae compare double_folded --out out``).
Bad input gives a clear message on stderr and a non-zero exit code (2: bad input, 3: the
run failed part-way), never a traceback.
"""

from __future__ import annotations

import argparse
import os
import sys

from .cli_commands import (
    _animate,
    _bench,
    _cache,
    _compare,
    _design,
    _events,
    _examples,
    _iterate,
    _plot,
    _run,
    _schema,
    _sensitivities,
    _structure,
    _sweep,
)
from .core.errors import CmmError, SolverError


def _compiled_flags(parser: argparse.ArgumentParser, what: str = "IDA's segments") -> None:
    """--compiled / --no-compiled (one of them); neither: "auto" (C where the build is
    cached or short)."""
    p = parser.add_mutually_exclusive_group()
    p.add_argument("--compiled", dest="compiled", action="store_const", const=True,
                   default="auto", help=f"run {what} in C, built now if need be "
                   "(needs a C compiler; cached); default: in C where built already or "
                   "where the build is short")
    p.add_argument("--no-compiled", dest="compiled", action="store_const", const=False,
                   help=f"run {what} in Python (CasADi's virtual machine)")


def _branch(text: str) -> str | tuple[str, int]:
    """``--branch``: "continue" or JOINT:SIGN with SIGN +1, -1, + or -."""
    if text == "continue":
        return text
    joint, _, sign = text.rpartition(":")
    signs = {"+1": 1, "+": 1, "1": 1, "-1": -1, "-": -1}
    if not joint or sign not in signs:
        raise argparse.ArgumentTypeError(
            f"expected 'continue' or JOINT:SIGN with SIGN +1 or -1 (e.g. G1:+1), got {text!r}")
    return joint, signs[sign]


def _positive_int(text: str) -> int:
    """An integer >= 1 (``--workers``)."""
    try:
        n = int(text)
    except ValueError:
        n = 0
    if n < 1:
        raise argparse.ArgumentTypeError(f"expected a whole number >= 1, got {text!r}")
    return n


def _common(p: argparse.ArgumentParser, model_help: str = "mechanism TOML file or the "
            "name of a shipped example (cmm-dae examples lists them)") -> None:
    """The arguments every simulating command takes: the model, the end time, progress."""
    p.add_argument("model", help=model_help)
    p.add_argument("--t-end", type=float, default=10.0, help="end time, s (default 10)")
    p.add_argument("--progress", action="store_true",
                   help="progress bar of the simulated time on stderr")


def _simulating(sub) -> None:
    """``run``, ``iterate``, ``compare``."""
    common = _common
    r = sub.add_parser("run", help="simulate a model with IDA and print a summary")
    common(r)
    r.add_argument("--rtol", type=float, default=1e-8, help="relative tolerance (1e-8)")
    r.add_argument("--atol", type=float, default=None,
                   help="absolute tolerance (default: 1e-2 of rtol)")
    r.add_argument("--output-dt", type=float, default=0.01, help="output spacing, s (0.01)")
    r.add_argument("--csv", help="write every series to this CSV file")
    r.add_argument("--save", help="save the Result to this .npz file")
    r.add_argument("--force", action="store_true", help="overwrite --csv / --save files")
    _compiled_flags(r)
    r.add_argument("--linsolver", choices=("auto", "dense", "sparse"), default="auto",
                   help="IDA's linear solver (auto: sparse from 120 unknowns where at most "
                        "5%% of the Jacobian is nonzero; in C, band LU where it reorders "
                        "into a narrow band)")
    r.add_argument("--branch", type=_branch, default="continue", metavar="JOINT:SIGN",
                   help="at singular positions take the branch on which JOINT moves with "
                        "SIGN (+1 or -1), e.g. G1:+1 (default: continue, the branch of the "
                        "motion)")
    r.set_defaults(func=_run)

    i = sub.add_parser("iterate", help="simulate a model with the paper's fixed-step algorithm")
    common(i)
    i.add_argument("--dt", type=float, default=0.01, help="fixed step, s (0.01, as the paper)")
    i.add_argument("--csv", help="write every series to this CSV file")
    i.add_argument("--save", help="save the Result to this .npz file")
    i.add_argument("--force", action="store_true", help="overwrite --csv / --save files")
    _compiled_flags(i, "the fixed steps")
    i.set_defaults(func=_iterate)

    c = sub.add_parser("compare", help="IDA vs the iterative algorithm: report with figures")
    common(c)
    c.add_argument("--dt", type=float, default=0.01, help="iterative step and output spacing")
    c.add_argument("--rtol", type=float, default=1e-8, help="IDA relative tolerance (1e-8)")
    c.add_argument("--out", required=True, help="directory for report.md/.html and PNGs")
    c.add_argument("--no-work-precision", action="store_true",
                   help="skip the work-precision sweep (a few seconds)")
    c.add_argument("--force", action="store_true", help="overwrite an existing report")
    c.set_defaults(func=_compare)

def _viewing(sub) -> None:
    """``events``, ``structure``, ``animate``, ``plot``."""
    e = sub.add_parser("events", help="event table of a model run or of a saved result")
    e.add_argument("source", help="model file or example name, or a saved result (.npz)")
    e.add_argument("--t-end", type=float, default=None,
                   help="end time for a model, s (10; not for a saved result)")
    e.add_argument("--rtol", type=float, default=None,
                   help="IDA relative tolerance for a model (1e-8, as run's)")
    e.set_defaults(func=_events)

    s = sub.add_parser("structure", help="mobility, active parts and Assur groups")
    s.add_argument("model", help="model file or example name")
    s.set_defaults(func=_structure)

    a = sub.add_parser("animate", help="GIF of the mechanism moving (locked joints in red)")
    a.add_argument("source", help="model file or example name, or a saved result (.npz)")
    a.add_argument("--out", required=True, help="output .gif")
    a.add_argument("--t-end", type=float, default=None,
                   help="end time for a model, s (10; not for a saved result)")
    a.add_argument("--fps", type=int, default=20, help="frames per second (20)")
    a.add_argument("--frames", type=int, default=120, help="most frames (120)")
    a.add_argument("--force", action="store_true", help="overwrite an existing file")
    a.set_defaults(func=_animate)

    p = sub.add_parser("plot", help="paper-style figures of one run")
    p.add_argument("source", help="model file or example name, or a saved result (.npz)")
    p.add_argument("--out", required=True, help="directory for the PNGs")
    p.add_argument("--t-end", type=float, default=None,
                   help="end time for a model, s (10; not for a saved result)")
    p.add_argument("--force", action="store_true", help="overwrite existing PNGs")
    p.set_defaults(func=_plot)

def _studies(sub) -> None:
    """``sweep``, ``sensitivities``, ``design``, ``examples``, ``schema``, ``bench``."""
    common = _common
    sw = sub.add_parser("sweep", help="parameter sweep (local processes or a Dask cluster)")
    sw.add_argument("model", help="model file or example name")
    sw.add_argument("--param", action="append", default=[], metavar="PATH=A:B:N",
                    help="e.g. joints.D.spring.stiffness=0.5:3:20 (repeat for a grid)")
    sw.add_argument("--out", required=True, help="CSV written as runs finish (and resumed)")
    sw.add_argument("--t-end", type=float, default=10.0, help="end time, s (10)")
    sw.add_argument("--rtol", type=float, default=1e-8, help="IDA relative tolerance (1e-8)")
    sw.add_argument("--output-dt", type=float, default=0.01,
                    help="output spacing, s (0.01; the events and peak efforts do not "
                    "depend on it)")
    sw.add_argument("--workers", type=_positive_int, default=None,
                    help="local processes (all cores)")
    sw.add_argument("--scheduler", help="dask scheduler address, e.g. tcp://host:8786")
    _compiled_flags(sw)
    sw.set_defaults(func=_sweep)

    se = sub.add_parser("sensitivities", help="d(event times)/d(parameters), exact through "
                        "every event")
    common(se)
    se.add_argument("--param", action="append", default=[], metavar="PATH",
                    help="a dotted model path, e.g. joints.E.limits.upper (repeat)")
    se.add_argument("--rtol", type=float, default=1e-8, help="IDA relative tolerance (1e-8)")
    se.add_argument("--error-control", action="store_true",
                    help="keep the sensitivities in IDA's error test (slower)")
    se.set_defaults(func=_sensitivities)

    de = sub.add_parser("design", help="optimise parameters on exact gradients (a TOML "
                        "study file: model, params with bounds, objective, targets)")
    de.add_argument("spec", help="the design study file (TOML)")
    de.add_argument("--out", help="report directory (default: the file's 'out')")
    de.add_argument("--force", action="store_true", help="overwrite an existing report")
    de.set_defaults(func=_design)

    ex = sub.add_parser("examples", help="list the shipped example models")
    ex.set_defaults(func=_examples)

    ca = sub.add_parser("cache", help="the compiled-library cache: its size, its files, "
                        "clear it")
    ca.add_argument("--list", action="store_true", help="list every library, most "
                    "recently used first")
    ca.add_argument("--clear", action="store_true", help="remove every cached library")
    ca.set_defaults(func=_cache)

    sc = sub.add_parser("schema", help="print the JSON Schema of model files (or the "
                        "model-file reference with --markdown)")
    sc.add_argument("--markdown", action="store_true", help="the reference as Markdown")
    sc.set_defaults(func=_schema)

    bn = sub.add_parser("bench", help="benchmark models: IDA vs the iterative algorithm")
    bn.add_argument("models", nargs="*", help="model files (default: every shipped model)")
    bn.add_argument("--t-end", type=float, default=10.0, help="simulated time, s (10)")
    bn.add_argument("--rtol", type=float, default=1e-8, help="IDA relative tolerance (1e-8)")
    bn.add_argument("--dt", type=float, default=0.01, help="iterative step, s (0.01)")
    bn.add_argument("--repeat", type=int, default=3, help="warm repeats, best taken (3)")
    bn.add_argument("--no-compiled", action="store_true",
                    help="leave out the compiled segment (whose first build takes seconds)")
    bn.add_argument("--chain", action="store_true",
                    help="also time chains of 8, 16 and 32 four-bar loops (growth with size)")
    bn.add_argument("--peers", action="store_true",
                    help="time cmm_dae against MuJoCo (extra 'peers') at equal accuracy on "
                         "IFToMM A02 chains of --loops four-bar loops, 2 s, on Andrews' "
                         "squeezer, 0.03 s, and (with Exudyn too) on the spatial Bennett "
                         "linkage, 2 s")
    bn.add_argument("--loops", type=int, nargs="+", default=[1, 8, 32],
                    help="with --peers: loop counts (1 8 32)")
    bn.add_argument("--steps", type=float, nargs="+", default=[1e-5, 2e-6, 1e-6],
                    help="with --peers: MuJoCo's steps on the squeezer, s (1e-5 2e-6 1e-6)")
    bn.set_defaults(func=_bench)

def build_parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(prog="cmm-dae", description="Constrained metamorphic "
                                 "mechanisms: index-reduced DAE on SUNDIALS IDA, checked "
                                 "against the paper's fixed-step iterative algorithm.")
    sub = ap.add_subparsers(dest="command", required=True)

    _simulating(sub)
    _viewing(sub)
    _studies(sub)
    return ap


def main(argv: list[str] | None = None) -> int:
    """Entry point of ``cmm-dae``; returns the exit code (0 done, 2 bad input, 3 a run
    failed part-way, 130 interrupted)."""
    args = build_parser().parse_args(argv)
    try:
        return args.func(args)
    except SolverError as err:
        print(f"cmm-dae: {err}", file=sys.stderr)
        return 3
    except CmmError as err:
        print(f"cmm-dae: {err}", file=sys.stderr)
        return 2
    except BrokenPipeError:  # `cmm-dae ... | head`: the reader left; nothing to say
        _quiet_stdout()
        return 0
    except OSError as err:
        print(f"cmm-dae: {err.strerror or err}" + (f": '{err.filename}'" if err.filename
                                                     else ""), file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("cmm-dae: interrupted", file=sys.stderr)
        return 130


def _quiet_stdout() -> None:
    """Point stdout at /dev/null so that the interpreter's final flush into a closed pipe
    says nothing either."""
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
    except OSError:
        pass


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
