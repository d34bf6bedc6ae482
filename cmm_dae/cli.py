"""Command line interface ``cmm-dae``.

Commands: ``run``, ``iterate``, ``compare``, ``events``, ``structure``, ``animate``, ``plot``,
``sweep``, ``sensitivities``, ``design``, ``bench``, ``examples``, ``schema``. A model is a
TOML file or the name of a shipped example (``cmm-dae compare double_folded --out out``).
Bad input gives a clear message on stderr and a non-zero exit code (2: bad input, 3: the
run failed part-way), never a traceback.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from .core.errors import CmmError, SolverError


def _load(arg: str):
    """A model given as a file path or as the name of a shipped example."""
    from . import load
    from .description.library import model_path

    return load(model_path(arg))


def _summary(res) -> None:
    s = res.stats
    print(f"{res.meta['mechanism']} ({s.method}): t = {res.t[0]:g} .. {res.t[-1]:g} s, "
          f"{res.t.size} samples, {s.steps} steps, {s.nfev} residual / {s.njev} Jacobian "
          f"evaluations, {len(res.events)} events, wall {s.wall_time * 1e3:.1f} ms "
          f"(model build {s.build_time * 1e3:.1f} ms)")
    pos, vel = res.drift
    print(f"constraint drift: |Phi| <= {pos:.2e}, |Phi'| <= {vel:.2e}")
    for name in res.meta["drivers"]:
        e = res.driver(name).effort
        print(f"driver {name}: effort {e.min():.6g} .. {e.max():.6g}")
    if res.events:
        print(res.event_table())


def _refuse_overwrite(paths, force: bool) -> None:
    """The one overwrite policy of every command: files the command would write that
    exist already are refused up front, before anything is computed, unless --force."""
    there = [str(p) for p in paths if p is not None and Path(p).exists()]
    if there and not force:
        raise CmmError(f"would overwrite {', '.join(there)}; pass --force to replace "
                       f"{'it' if len(there) == 1 else 'them'} or choose another path")


def _save(res, args) -> list[str]:
    """Write --csv and --save (a failed or interrupted run's partial Result too); the
    lines to print. Written before anything is printed: with stdout closed
    (``| head -1``) the files still come."""
    done = []
    if getattr(args, "csv", None):
        done.append(f"wrote {res.to_csv(args.csv)}")
    if getattr(args, "save", None):
        done.append(f"wrote {res.save(args.save)}")
    return done


def _finish(res, args) -> int:
    """Save, then summarise a run of ``run`` / ``iterate``; exit code 0, or 3 (failed
    part-way) / 130 (interrupted) with what was computed saved all the same."""
    written = _save(res, args)
    if not res.success:
        print(f"cmm-dae: {res.message} (status: {res.status}); the result up to t = "
              f"{res.t[-1]:.9g} s" + (" is saved" if written else " is kept in memory "
                                      "only: give --save or --csv to keep it"),
              file=sys.stderr)
    _summary(res)
    for line in written:
        print(line)
    return 0 if res.success else (130 if res.status == "interrupted" else 3)


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


def _run(args: argparse.Namespace) -> int:
    from . import simulate

    _refuse_overwrite((args.csv, args.save), args.force)
    res = simulate(_load(args.model), args.t_end, method="ida", rtol=args.rtol, atol=args.atol,
                   output_dt=args.output_dt, progress=args.progress, compiled=args.compiled,
                   linsolver=args.linsolver, branch=args.branch, throw=False)
    return _finish(res, args)


def _iterate(args: argparse.Namespace) -> int:
    from . import simulate

    _refuse_overwrite((args.csv, args.save), args.force)
    res = simulate(_load(args.model), args.t_end, method="iterative", dt=args.dt,
                   progress=args.progress, throw=False)
    return _finish(res, args)


def _compare(args: argparse.Namespace) -> int:
    from . import Model, compare, simulate
    from .report.plots import work_precision as wp_plot
    from .studies.precision import work_precision

    out = Path(args.out)
    _refuse_overwrite([out / "report.md", out / "report.html"], args.force)
    mech = _load(args.model)
    model = Model(mech)
    runs = {"IDA": dict(method="ida", rtol=args.rtol, atol=args.rtol * 1e-2,
                        output_dt=args.dt),
            "iterative": dict(method="iterative", dt=args.dt)}
    res, notes = [], []
    for name, kw in runs.items():  # a failing run still gives its partial Result
        r = simulate(mech, args.t_end, model=model, throw=False, progress=args.progress, **kw)
        if not r.success:
            notes.append(f"the {name} run failed at t = {r.t[-1]:.6g} s ({r.status}): "
                         f"{r.message}; the comparison covers what both runs reached")
        res.append(r)
    cmp = compare(*res)
    out.mkdir(parents=True, exist_ok=True)
    if args.no_work_precision:
        pass
    elif not mech.drivers:
        notes.append("no work-precision study: the mechanism has no driver")
    else:
        try:
            wp = work_precision(mech, t_end=args.t_end, model=model)
        except CmmError as e:
            notes.append(f"work-precision study left out: {e}")
        else:
            cmp.work_precision = wp
            notes += [f"work-precision run {r.method} {r.setting} failed ({r.status})"
                      for r in wp.rows if not r.success]
            cmp.extra_figures["Work-precision: error in the driving effort vs wall time"] = \
                wp_plot(wp.rows, out / "work_precision.png",
                        f"{mech.name}: driving-effort error vs wall time\n(reference: IDA at "
                        f"rtol {wp.reference_rtol:g}, errors away from events)")
    cmp.notes = notes
    path = cmp.write_report(out)
    print(cmp.table())
    for n in notes:
        print(f"note: {n}", file=sys.stderr)
    print(f"wrote {path} and {path.with_suffix('.html')}")
    return 0 if all(r.success for r in res) else 3


def _result_of(source: str, t_end: float):
    """A saved Result (.npz) or a run of a model file (.toml); anything else is refused."""
    from . import load_result, simulate
    from .description.library import model_path

    path = model_path(source)
    if path.suffix == ".npz":
        return load_result(path)
    if path.suffix == ".toml":
        return simulate(_load(str(path)), t_end)
    raise CmmError(f"'{source}': expected a model file (.toml) or a saved result (.npz), "
                   f"not a '{path.suffix or 'suffix-less'}' file")


def _events(args: argparse.Namespace) -> int:
    print(_result_of(args.source, args.t_end).event_table())
    return 0


def _structure(args: argparse.Namespace) -> int:
    from .description.structure import structure

    print(structure(_load(args.model)))
    return 0


def _animate(args: argparse.Namespace) -> int:
    from .report.animation import animate, gif_path

    gif_path(args.out, "--out")  # before the run, not after it
    _refuse_overwrite([args.out], args.force)
    res = _result_of(args.source, args.t_end)
    print(f"wrote {animate(res, args.out, fps=args.fps, max_frames=args.frames)}")
    return 0


def _plot(args: argparse.Namespace) -> int:
    from .report import plots

    out = Path(args.out)
    _refuse_overwrite(sorted(out.glob("*.png")) if out.is_dir() else [], args.force)
    res = _result_of(args.source, args.t_end)
    out.mkdir(parents=True, exist_ok=True)
    written = []
    if res.meta["drivers"]:
        written.append(plots.driving_effort([res], out / "driving.png"))
    meta = res.watched_joints()
    if meta:
        written.append(plots.joint_motion([res], meta, out / "joints.png"))
        written += [plots.joint_forces([res], j, out / f"forces_{j}.png") for j in meta]
    written.append(plots.timeline([res], out / "timeline.png"))
    for p in written:
        print(f"wrote {p}")
    return 0


def _bench(args: argparse.Namespace) -> int:
    from .description.library import examples_dir, model_path
    from .studies.bench import bench_models, chain_growth, chain_table, table

    if args.repeat < 1:
        raise CmmError(f"--repeat must be at least 1, not {args.repeat}")
    if args.peers:
        from .studies.peers import compare_a02, peers_table

        if args.models or args.chain:
            raise CmmError("--peers runs its own problem (A02 with --loops): give no "
                           "models and no --chain with it")
        if not args.loops or any(n < 1 for n in args.loops):
            raise CmmError(f"--loops must be integers >= 1, not {args.loops}")
        print(peers_table([compare_a02(n, repeat=args.repeat) for n in args.loops]))
        return 0
    paths = [model_path(m) for m in args.models] or sorted(examples_dir().glob("*.toml"))
    print(table(bench_models(paths, t_end=args.t_end, rtol=args.rtol, dt=args.dt,
                             repeat=args.repeat, compiled=not args.no_compiled)))
    if args.chain:
        print()
        print(chain_table(*chain_growth(rtol=args.rtol, repeat=args.repeat)))
    return 0


def _sweep(args: argparse.Namespace) -> int:
    from .studies.sweep import parse_range, sweep

    mech = _load(args.model)
    pairs = [parse_range(p) for p in args.param]
    params = dict(pairs)
    if not params:
        raise CmmError("give at least one --param PATH=A:B:N")
    twice = sorted({k for k, _ in pairs if sum(k == x for x, _ in pairs) > 1})
    if twice:
        raise CmmError(f"--param {', '.join(twice)} given more than once; give each "
                       "parameter one range (a grid takes one --param per parameter)")
    client = None
    if args.scheduler:
        try:
            from distributed import Client
        except ImportError:
            raise CmmError("--scheduler needs dask.distributed: pip install "
                           "'cmm_dae[scale]'") from None
        try:
            client = Client(args.scheduler, timeout="20s")
        except (ValueError, OSError, TimeoutError) as e:
            raise CmmError(f"--scheduler {args.scheduler!r}: no Dask scheduler there "
                           f"({type(e).__name__}: {e}); expected an address such as "
                           "tcp://host:8786") from None
    table = sweep(mech, params, t_end=args.t_end, client=client, workers=args.workers,
                  checkpoint=args.out, progress=True, rtol=args.rtol,
                  compiled=args.compiled)
    ok = sum(r["status"] == "success" for r in table.rows)
    print(f"{len(table)} runs ({ok} successful) -> {args.out}")
    return 0


def _examples(args: argparse.Namespace) -> int:
    from .description.library import example, examples

    for name in examples():
        print(f"{name:<28} {example(name)}")
    return 0


def _schema(args: argparse.Namespace) -> int:
    from .description import schema

    sys.stdout.write(schema.reference_markdown() if args.markdown else schema.json_text())
    return 0


def _sensitivities(args: argparse.Namespace) -> int:
    from . import sensitivities

    if not args.param:
        raise CmmError("give at least one --param PATH (e.g. --param "
                       "joints.D.spring.stiffness)")
    s = sensitivities(_load(args.model), args.param, args.t_end, rtol=args.rtol,
                      atol=args.rtol * 1e-2, error_control=args.error_control,
                      progress=args.progress)
    _summary(s.result)
    print()
    print("d t_event / d parameter (s per unit of the parameter):")
    print(s.event_table())
    for note in s.notes:
        print(f"note: {note}")
    print(f"sensitivities of {len(s.params)} parameter(s) in {s.wall_time:.2f} s")
    return 0


def _design(args: argparse.Namespace) -> int:
    from .studies.design import REPORT_FILES, DesignError
    from .studies.studyfile import design_spec

    spec = design_spec(args.spec)
    out = Path(args.out) if args.out else spec.pop("out")
    # refused before the optimisation (tens of seconds), not after it
    _refuse_overwrite([out / n for n in REPORT_FILES], args.force)
    try:
        d = spec.pop("run_design")()
    except DesignError as e:
        print(f"cmm-dae: {e}", file=sys.stderr)
        return 3
    print(d.summary())
    print(f"wrote {d.report(out, overwrite=args.force)}")
    return 0


def build_parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(prog="cmm-dae", description="Constrained metamorphic "
                                 "mechanisms: index-reduced DAE on SUNDIALS IDA, checked "
                                 "against the paper's fixed-step iterative algorithm.")
    sub = ap.add_subparsers(dest="command", required=True)

    def common(p, model_help="mechanism TOML file or the name of a shipped example "
               "(cmm-dae examples lists them)"):
        p.add_argument("model", help=model_help)
        p.add_argument("--t-end", type=float, default=10.0, help="end time, s (default 10)")
        p.add_argument("--progress", action="store_true",
                       help="progress bar of the simulated time on stderr")

    r = sub.add_parser("run", help="simulate a model with IDA and print a summary")
    common(r)
    r.add_argument("--rtol", type=float, default=1e-8, help="relative tolerance (1e-8)")
    r.add_argument("--atol", type=float, default=None,
                   help="absolute tolerance (default: 1e-2 of rtol)")
    r.add_argument("--output-dt", type=float, default=0.01, help="output spacing, s (0.01)")
    r.add_argument("--csv", help="write every series to this CSV file")
    r.add_argument("--save", help="save the Result to this .npz file")
    r.add_argument("--force", action="store_true", help="overwrite --csv / --save files")
    r.add_argument("--compiled", action="store_true",
                   help="run IDA's segments in C (needs a C compiler; built once, cached)")
    r.add_argument("--linsolver", choices=("auto", "dense", "sparse"), default="auto",
                   help="IDA's linear solver (auto: sparse from 300 unknowns)")
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

    e = sub.add_parser("events", help="event table of a model run or of a saved result")
    e.add_argument("source", help="model file or example name, or a saved result (.npz)")
    e.add_argument("--t-end", type=float, default=10.0, help="end time for a model, s")
    e.set_defaults(func=_events)

    s = sub.add_parser("structure", help="mobility, active parts and Assur groups")
    s.add_argument("model", help="model file or example name")
    s.set_defaults(func=_structure)

    a = sub.add_parser("animate", help="GIF of the mechanism moving (locked joints in red)")
    a.add_argument("source", help="model file or example name, or a saved result (.npz)")
    a.add_argument("--out", required=True, help="output .gif")
    a.add_argument("--t-end", type=float, default=10.0, help="end time for a model, s")
    a.add_argument("--fps", type=int, default=20, help="frames per second (20)")
    a.add_argument("--frames", type=int, default=120, help="most frames (120)")
    a.add_argument("--force", action="store_true", help="overwrite an existing file")
    a.set_defaults(func=_animate)

    p = sub.add_parser("plot", help="paper-style figures of one run")
    p.add_argument("source", help="model file or example name, or a saved result (.npz)")
    p.add_argument("--out", required=True, help="directory for the PNGs")
    p.add_argument("--t-end", type=float, default=10.0, help="end time for a model, s")
    p.add_argument("--force", action="store_true", help="overwrite existing PNGs")
    p.set_defaults(func=_plot)
    sw = sub.add_parser("sweep", help="parameter sweep (local processes or a Dask cluster)")
    sw.add_argument("model", help="model file or example name")
    sw.add_argument("--param", action="append", default=[], metavar="PATH=A:B:N",
                    help="e.g. joints.D.spring.stiffness=0.5:3:20 (repeat for a grid)")
    sw.add_argument("--out", required=True, help="CSV written as runs finish (and resumed)")
    sw.add_argument("--t-end", type=float, default=10.0, help="end time, s (10)")
    sw.add_argument("--rtol", type=float, default=1e-8, help="IDA relative tolerance (1e-8)")
    sw.add_argument("--workers", type=_positive_int, default=None,
                    help="local processes (all cores)")
    sw.add_argument("--scheduler", help="dask scheduler address, e.g. tcp://host:8786")
    sw.add_argument("--compiled", action="store_true",
                    help="run IDA's segments in C (needs a C compiler; built once, cached)")
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
                         "IFToMM A02 chains of --loops four-bar loops, 2 s")
    bn.add_argument("--loops", type=int, nargs="+", default=[1, 8, 32],
                    help="with --peers: loop counts (1 8 32)")
    bn.set_defaults(func=_bench)
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
    import os

    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
    except OSError:
        pass


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
