"""The commands of ``cmm-dae`` (:mod:`cmm_dae.cli` parses the arguments and calls them):
each reads its arguments, runs what it names and prints or writes the result; bad input
raises a CmmError that :func:`cmm_dae.cli.main` turns into a message and an exit code."""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from .core.errors import CmmError


def _load(arg: str):
    """A model given as a file path or as the name of a shipped example."""
    from . import load
    from .description.library import model_path

    return load(model_path(arg))


#: Events a run's summary lists at most (the first and last halves; `events` lists all).
SUMMARY_EVENTS = 40


def _summary(res) -> None:
    s = res.stats
    how = f"{s.method}, in C" if res.meta.get("compiled") else s.method
    print(f"{res.layout.mechanism} ({how}): t = {res.t[0]:g} .. {res.t[-1]:g} s, "
          f"{res.t.size} samples, {s.steps} steps, {s.nfev} residual / {s.njev} Jacobian "
          f"evaluations, {len(res.events)} events, wall {s.wall_time * 1e3:.1f} ms "
          f"(model build {s.build_time * 1e3:.1f} ms)")
    pos, vel = res.drift
    print(f"constraint drift: |Phi| <= {pos:.2e}, |Phi'| <= {vel:.2e}")
    for name in res.layout.drivers:
        d = res.driver(name)  # extremes over every step and event, not the output grid
        print(f"driver {name}: effort {d.low:.6g} (t = {d.t_low:.6g} s) .. {d.high:.6g} "
              f"(t = {d.t_high:.6g} s)")
    if res.events:
        print(res.event_table(limit=SUMMARY_EVENTS))


def _refuse_overwrite(paths, force: bool) -> None:
    """The one overwrite policy of every command: files the command would write that
    exist already are refused up front, before anything is computed, unless --force; and
    two outputs of one command never share a file (the second would replace the first)."""
    given = [Path(p).resolve() for p in paths if p is not None]
    if len(set(given)) < len(given):
        same = next(p for p in given if given.count(p) > 1)
        raise CmmError(f"two outputs would both be written to '{same}' (--csv and --save "
                       "take different files)")
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
                   progress=args.progress, throw=False, compiled=args.compiled)
    return _finish(res, args)


def _compare(args: argparse.Namespace) -> int:
    from . import Model, compare, simulate
    from .report.plots import work_precision as wp_plot
    from .studies.precision import work_precision

    out = Path(args.out)
    _refuse_overwrite([out / "report.md", out / "report.html"], args.force)
    mech = _load(args.model)
    model = Model(mech)
    runs = {"IDA": dict(method="ida", rtol=args.rtol, output_dt=args.dt),
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
            wp = work_precision(mech, t_end=args.t_end, model=model, grid=args.dt)
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


def _result_of(source: str, t_end: float | None, rtol: float | None = None):
    """A saved Result (.npz) or a run of a model file (.toml) to ``t_end`` (10 s where
    None; at ``rtol``, or the default); anything else is refused, and so are a ``t_end``
    or an ``rtol`` given for a saved result (its run is over: they would be ignored)."""
    from . import load_result, simulate
    from .description.library import model_path

    path = model_path(source)
    if path.suffix == ".npz" or _is_zip(path):  # (Result.save writes any name it is given)
        res = load_result(path)
        if t_end is not None or rtol is not None:
            raise CmmError(f"'{source}' is a saved result (its run ended at "
                           f"t = {res.t[-1]:g} s): --t-end and --rtol set a model's run")
        return res
    if path.suffix == ".toml":
        return simulate(_load(str(path)), 10.0 if t_end is None else t_end,
                        **({} if rtol is None else {"rtol": rtol}))
    raise CmmError(f"'{source}': expected a model file (.toml) or a saved result (.npz), "
                   f"not a '{path.suffix or 'suffix-less'}' file")


def _is_zip(path: Path) -> bool:
    try:
        with path.open("rb") as f:
            return f.read(2) == b"PK"
    except OSError:
        return False


def _events(args: argparse.Namespace) -> int:
    print(_result_of(args.source, args.t_end, args.rtol).event_table())
    return 0


def _structure(args: argparse.Namespace) -> int:
    from .simulation.structure import structure

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
    if res.layout.drivers:
        written.append(plots.driving_effort([res], out / "driving.png"))
    watched = res.watched_joints()
    if watched:
        written.append(plots.joint_motion([res], watched, out / "joints.png"))
        written += [plots.joint_forces([res], j, out / f"forces_{j}.png") for j in watched]
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
        from .studies.peers import STEPS, compare_a02, peers_table

        if args.models or args.chain:
            raise CmmError("--peers runs its own problem (A02 with --loops): give no "
                           "models and no --chain with it")
        if not args.loops or any(n < 1 for n in args.loops):
            raise CmmError(f"--loops must be integers >= 1, not {args.loops}")
        if not args.steps or not all(0.0 < h <= 1e-3 for h in args.steps):
            raise CmmError(f"--steps must be MuJoCo steps in (0, 1e-3] s, not {args.steps}")
        from .studies.peers_andrews import andrews_table, compare_andrews

        print(peers_table([compare_a02(n, h=h, repeat=args.repeat) for n in args.loops
                           for h in STEPS]))
        print()
        print(andrews_table([compare_andrews(h, repeat=args.repeat) for h in args.steps]))
        from .studies.peers_exudyn import compare_a02_exudyn, exudyn_available, exudyn_table

        print()
        print(exudyn_table([compare_a02_exudyn(n, repeat=args.repeat) for n in args.loops])
              if exudyn_available() else
              "Exudyn is not installed (pip install 'cmm_dae[peers]'): no comparison with it")
        from .studies.peers_bennett import bennett_table, compare_bennett

        print()
        print(bennett_table(compare_bennett(repeat=args.repeat)))
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
                  output_dt=args.output_dt, compiled=args.compiled)
    ok = sum(r["status"] == "success" for r in table.rows)
    print(f"{len(table)} runs ({ok} successful) -> {args.out}")
    return 0


def _examples(args: argparse.Namespace) -> int:
    from .description.library import example, examples

    for name in examples():
        print(f"{name:<28} {example(name)}")
    return 0


def _cache(args: argparse.Namespace) -> int:
    from .equations import libcache
    from .equations.codegen import cache_dir

    where = cache_dir()
    if args.clear:
        n, freed = libcache.clear()
        print(f"removed {n} libraries ({freed / 2**20:.1f} MB) from {where}")
        return 0
    items = libcache.entries()
    total = sum(e.size for e in items)
    print(f"{where}: {len(items)} libraries, {total / 2**20:.1f} MB of "
          f"{libcache.limit() / 2**20:.0f} MB (CMM_DAE_CACHE_MB; the least recently used "
          "go first)")
    if args.list:
        for e in reversed(items):
            print(f"  {e.path.name:<34} {e.size / 2**10:9.1f} kB  last used "
                  f"{time.strftime('%Y-%m-%d %H:%M', time.localtime(e.used))}")
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
                      error_control=args.error_control, progress=args.progress)
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
