"""Command line: ``cmm-dae run MODEL``, ``cmm-dae events MODEL|RESULT``, ``cmm-dae structure``.

Bad input gives a clear one-paragraph message on stderr and a non-zero exit code, never a
traceback.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from .errors import CmmError, SolverError


def _run(args: argparse.Namespace) -> int:
    from . import load, run_dae

    mech = load(args.model)
    res = run_dae(mech, args.t_end, rtol=args.rtol, atol=args.atol, output_dt=args.output_dt)
    _summary(res)
    if args.csv:
        print(f"wrote {res.to_csv(args.csv)}")
    if args.save:
        print(f"wrote {res.save(args.save)}")
    return 0


def _summary(res) -> None:
    s = res.stats
    print(f"{res.meta['mechanism']}: t = {res.t[0]:g} .. {res.t[-1]:g} s, {res.t.size} samples, "
          f"{s.steps} steps, {s.nfev} residual / {s.njev} Jacobian evaluations, "
          f"{len(res.events)} events, wall {s.wall_time * 1e3:.1f} ms "
          f"(model build {s.build_time * 1e3:.1f} ms)")
    pos, vel = res.drift
    print(f"constraint drift: |Phi| <= {pos:.2e}, |Phi'| <= {vel:.2e}")
    for name in res.meta["drivers"]:
        e = res.driver(name).effort
        print(f"driver {name}: effort {e.min():.6g} .. {e.max():.6g}")
    if res.events:
        print(res.event_table())


def _events(args: argparse.Namespace) -> int:
    from . import load, load_result, run_dae

    path = Path(args.source)
    res = load_result(path) if path.suffix == ".npz" else run_dae(load(path), args.t_end)
    print(res.event_table())
    return 0


def _structure(args: argparse.Namespace) -> int:
    from . import load
    from .structure import structure

    print(structure(load(args.model)))
    return 0


def build_parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(prog="cmm-dae", description="Constrained metamorphic "
                                 "mechanisms: index-reduced DAE on SUNDIALS IDA.")
    sub = ap.add_subparsers(dest="command", required=True)
    r = sub.add_parser("run", help="simulate a model file with IDA and print a summary")
    r.add_argument("model", help="mechanism TOML file")
    r.add_argument("--t-end", type=float, default=10.0, help="end time, s (default 10)")
    r.add_argument("--rtol", type=float, default=1e-8, help="relative tolerance (1e-8)")
    r.add_argument("--atol", type=float, default=1e-10, help="absolute tolerance (1e-10)")
    r.add_argument("--output-dt", type=float, default=0.01, help="output spacing, s (0.01)")
    r.add_argument("--csv", help="write every series to this CSV file")
    r.add_argument("--save", help="save the Result to this .npz file")
    r.set_defaults(func=_run)
    e = sub.add_parser("events", help="print the event table of a model run or a saved result")
    e.add_argument("source", help="mechanism TOML file or saved result (.npz)")
    e.add_argument("--t-end", type=float, default=10.0, help="end time for a model, s")
    e.set_defaults(func=_events)
    s = sub.add_parser("structure", help="mobility, active parts and Assur groups")
    s.add_argument("model", help="mechanism TOML file")
    s.set_defaults(func=_structure)
    return ap


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        return args.func(args)
    except SolverError as err:
        print(f"cmm-dae: {err}", file=sys.stderr)
        return 3
    except CmmError as err:
        print(f"cmm-dae: {err}", file=sys.stderr)
        return 2


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
