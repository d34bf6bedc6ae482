"""Parameter sweeps: many variants of one mechanism, on a local process pool by default or
on a Dask cluster when the caller passes a ``dask.distributed.Client``.

Rows come back ordered like the input cases; a variant that cannot assemble or fails
part-way is a row with its status and message, every other row is complete. Rows stream
to a checkpoint CSV as they finish, and a rerun with the same file skips the rows done.
"""

from __future__ import annotations

import csv
import inspect
import itertools
import math
import os
import sys
import time
from collections.abc import Callable, Iterable, Mapping
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from pathlib import Path
from typing import Any

import numpy as np

from ..core.errors import CmmError, ModelError, Problem
from ..core.progress import Bar
from ..description.mechanism import Mechanism
from ..description.params import with_params
from ..results.result import Result
from ..simulation.options import check_options
from ..simulation.runner import simulate

Metric = Callable[[Result], Mapping[str, float]]
#: Most cases in one sweep (a grid's size is the product of its value counts).
MAX_CASES = 1_000_000


def cases_from(params: Mapping[str, Iterable[float]] | list[Mapping[str, float]]
               ) -> list[dict[str, float]]:
    """A grid (dict of value lists: cartesian product, last key fastest) or explicit cases."""
    if isinstance(params, Mapping):
        keys = list(params)
        lists = [list(params[k]) for k in keys]
        n = math.prod(len(v) for v in lists)
        if n > MAX_CASES:
            raise ModelError(Problem("sweep", " x ".join(keys), f"a grid of {n:.3g} cases; "
                                     f"at most {MAX_CASES} in one sweep"))
        return [dict(zip(keys, combo, strict=True)) for combo in itertools.product(*lists)]
    cases = [dict(c) for c in params]
    if len(cases) > MAX_CASES:
        raise ModelError(Problem("sweep", "cases", f"{len(cases)} cases; at most {MAX_CASES}"))
    return cases


def default_metrics(res: Result) -> dict[str, float]:
    """Switching times per joint and kind (``t_limit_E_1`` = first limit event of E), peak
    |driving effort| per driver (over the whole solution: :class:`DriverSeries` ``low`` and
    ``high`` of :meth:`~cmm_dae.results.result.Result.driver`), the largest energy-balance
    residual."""
    out: dict[str, float] = {}
    count: dict[tuple[str, str], int] = {}
    for e in res.events:
        k = (e.kind, e.joint)
        count[k] = count.get(k, 0) + 1
        out[f"t_{e.kind}_{e.joint}_{count[k]}"] = e.t
    for d in res.layout.drivers:
        ds = res.driver(d)  # over every IDA step and event, not only the output grid
        out[f"peak_effort_{d}"] = float(max(abs(ds.low), abs(ds.high)))
    out["energy_residual"] = float(np.max(np.abs(res.energy().residual)))
    return out


def _check_run_options(mech: Mechanism, t_end: float, run_options: dict[str, Any]) -> None:
    """The run options checked once, up front (as :func:`simulate` checks them), so a bad
    one is one clear error rather than a failed row per case."""
    sig = inspect.signature(simulate)
    unknown = sorted(set(run_options) - set(sig.parameters) - {"mech", "t_end"})
    if unknown:
        names = ", ".join(k for k in list(sig.parameters)[2:] if k[0] != "_")
        raise ModelError(Problem("run", unknown[0], "not an option of a run; expected one "
                                 f"of {names}"))
    # the options check_options takes (by keyword), at simulate's defaults unless given
    checked = [k for k, p in inspect.signature(check_options).parameters.items()
               if p.kind is p.KEYWORD_ONLY and k != "model"]
    given = {k: run_options.get(k, sig.parameters[k].default) for k in checked}
    check_options(mech, run_options.get("method", "ida"), t_end, **given)


def run_case(mech: Mechanism, values: dict[str, float], t_end: float,
             metrics: Metric | None, run_options: dict[str, Any]) -> dict[str, Any]:
    """One sweep row; never raises for a failing variant (status and message say why)."""

    row: dict[str, Any] = dict(values)
    t0 = time.perf_counter()
    try:
        res = simulate(with_params(mech, values), t_end, throw=False, **run_options)
        row.update((metrics or default_metrics)(res))
        row["status"] = "success" if res.success else "failed"
        row["message"] = "" if res.success else " ".join(res.message.split())
        row["t_reached"] = float(res.t[-1])
    except CmmError as e:
        row.update(status="error", message=" ".join(str(e).split()), t_reached=math.nan)
    row["wall_s"] = time.perf_counter() - t0
    return row


class SweepTable:
    """Sweep results: one dict per case, in input order; ``columns`` is the union of keys."""

    def __init__(self, rows: list[dict[str, Any]]):
        self.rows = rows

    @property
    def columns(self) -> list[str]:
        cols: list[str] = []
        for r in self.rows:
            cols += [k for k in r if k not in cols]
        return cols

    def column(self, name: str) -> np.ndarray:
        """One column as an array (NaN where a row has no value)."""
        return np.array([r.get(name, math.nan) for r in self.rows], dtype=object
                        if any(isinstance(r.get(name), str) for r in self.rows) else float)

    def __len__(self) -> int:
        return len(self.rows)

    def to_csv(self, path: str | Path) -> Path:
        path = Path(path)
        cols = self.columns
        with path.open("w", newline="") as f:
            w = csv.DictWriter(f, fieldnames=cols, restval="")
            w.writeheader()
            w.writerows(self.rows)
        return path


def _key(values: Mapping[str, Any], names: list[str]) -> tuple:
    """A case's identity in a checkpoint: its parameter values (NaN where it has none)."""
    out = []
    for n in names:
        v = values.get(n, math.nan)
        v = float(v) if v not in ("", None) else math.nan
        out.append("nan" if math.isnan(v) else repr(v))
    return tuple(out)


def _read_checkpoint(path: Path, names: list[str]) -> dict[tuple, dict[str, Any]]:
    """Rows already done in a checkpoint file, by case key.

    A file that is not a checkpoint of this sweep (another CSV, anything else) is refused
    and left untouched. A last line torn by an interrupted write (no line end, or a row of
    the wrong width) is cut off, so that its case runs again and the next row is never
    glued onto it.
    """
    done: dict[tuple, dict[str, Any]] = {}
    if not path.exists():
        return done
    if not path.is_file():
        raise CmmError(f"checkpoint '{path}' is not a file")
    raw = path.read_bytes()
    if not raw:
        return done
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError:
        raise CmmError(f"'{path}' is not a sweep checkpoint (not UTF-8 text); it was left "
                       "untouched: choose another --out / checkpoint path") from None
    lines = text.splitlines(keepends=True)
    header = next(csv.reader([lines[0]]), [])
    needed = {"case", "status", *names}
    if not lines[0].endswith("\n") or header[:1] != ["case"] or not needed <= set(header):
        raise CmmError(f"'{path}' is not a checkpoint of this sweep (its first line should "
                       f"name the columns case, {', '.join(names)}, ..., status); it was left "
                       "untouched: choose another --out / checkpoint path")
    keep = [lines[0]]
    for line in lines[1:]:
        row = next(csv.reader([line]), [])
        if not line.endswith("\n") or len(row) != len(header):
            break  # torn: this row and anything after it is run again
        keep.append(line)
    if len(keep) < len(lines):
        path.write_text("".join(keep), encoding="utf-8")  # cut the torn tail
    for line in keep[1:]:
        row = dict(zip(header, next(csv.reader([line])), strict=True))
        parsed: dict[str, Any] = {}
        for k, v in row.items():
            if k in ("status", "message"):
                parsed[k] = v
                continue
            try:
                parsed[k] = float(v) if v != "" else math.nan
            except ValueError:
                parsed[k] = v
        try:
            done[_key(parsed, names)] = parsed
        except (KeyError, ValueError):
            continue
    return done


class _Checkpoint:
    """Rows appended to a CSV as they finish (header from the first row's keys + extras)."""

    def __init__(self, path: Path | None):
        self.path = path
        self.fields: list[str] | None = None

    def write(self, row: dict[str, Any]) -> None:
        if self.path is None:
            return
        new = not self.path.is_file() or self.path.stat().st_size == 0
        if self.fields is None:
            if new:
                self.fields = list(row)
            else:
                with self.path.open(newline="") as f:
                    self.fields = next(csv.reader(f), list(row))
        extra = [k for k in row if k not in self.fields]
        if extra:  # a metric the earlier rows lacked: rewrite the file with wider columns
            old = list(csv.DictReader(self.path.open(newline=""))) if not new else []
            self.fields += extra
            with self.path.open("w", newline="") as f:
                w = csv.DictWriter(f, fieldnames=self.fields, restval="")
                w.writeheader()
                w.writerows(old)
            new = False
        with self.path.open("a", newline="") as f:
            w = csv.DictWriter(f, fieldnames=self.fields, restval="")
            if new:
                w.writeheader()
            w.writerow(row)


def sweep(mech: Mechanism, params: Mapping[str, Iterable[float]] | list[Mapping[str, float]],
          *, t_end: float, metrics: Metric | None = None, client: Any = None,
          workers: int | None = None, checkpoint: str | Path | None = None,
          progress: bool | None = None, **run_options: Any) -> SweepTable:
    """Run :func:`cmm_dae.simulate` over parameter variants of ``mech``.

    Parameters
    ----------
    mech : Mechanism
    params : dict or list of dict
        Dotted model paths (see :func:`with_params`) to value lists (a grid) or a list of
        explicit cases.
    t_end : float
        End time of every run, s.
    metrics : callable or None
        ``f(Result) -> dict`` of numbers per row; default :func:`default_metrics`.
    client : dask.distributed.Client or None
        Run on that cluster; None: a local process pool of ``workers`` (default: all cores).
    checkpoint : path or None
        CSV that rows stream into as they finish; rows already in it are not run again.
    progress : bool or None
        A progress bar on stderr (default: for 20 or more cases on a terminal).
    **run_options
        Passed to :func:`cmm_dae.simulate` (method, rtol, atol, output_dt, dt, ...).
        The variants share their structure's model (the mechanism's values are inputs
        of its functions and of the generated code): the first run builds it, the others
        run on it (one build per structure, not per variant).

    Returns
    -------
    SweepTable
        One row per case, ordered like the input, with ``case``, the parameters, the
        metrics, ``status``, ``message``, ``t_reached`` and ``wall_s``.
    """
    if workers is not None and (isinstance(workers, bool) or not isinstance(workers, int)
                                or workers < 1):
        raise CmmError(f"workers: expected a whole number >= 1 of local processes or None "
                       f"(all cores), got {workers!r}")
    cases = cases_from(params)
    names = list(dict.fromkeys(k for c in cases for k in c))
    if cases:
        with_params(mech, cases[0])  # a bad path fails here, not in every worker
    _check_run_options(mech, t_end, run_options)
    ck_path = Path(checkpoint) if checkpoint is not None else None
    done = _read_checkpoint(ck_path, names) if ck_path is not None else {}
    rows: list[dict[str, Any] | None] = [None] * len(cases)
    todo = []
    for i, c in enumerate(cases):
        prev = done.get(_key(c, names))
        if prev is not None:
            rows[i] = dict(prev, case=i)
        else:
            todo.append(i)
    ck = _Checkpoint(ck_path)
    show = progress if progress is not None else (len(todo) >= 20 and sys.stderr.isatty())
    bar = Bar(len(todo), "sweep", "runs", enabled=show, every=0.0)

    def finish(i: int, row: dict[str, Any]) -> None:
        row = {"case": i, **row}
        rows[i] = row
        ck.write(row)
        bar.update(bar.value + 1)

    if client is not None:
        from distributed import as_completed

        futures = {client.submit(run_case, mech, cases[i], t_end, metrics, run_options,
                                 pure=False): i for i in todo}
        for fut in as_completed(futures):
            finish(futures[fut], fut.result())
    elif todo:
        n = workers or os.cpu_count() or 1
        if n == 1 or len(todo) == 1:
            for i in todo:
                finish(i, run_case(mech, cases[i], t_end, metrics, run_options))
        else:
            args = (mech, cases, t_end, metrics, run_options)
            _run_pool(todo, n, args, finish)
    bar.close()
    return SweepTable([r for r in rows if r is not None])


def _run_pool(todo: list[int], n: int, args: tuple, finish: Callable) -> None:
    """The cases ``todo`` on a pool of ``n`` local processes, each row to ``finish`` as it
    comes. A worker that dies (a crash, the kernel's out-of-memory killer) breaks the pool
    and every case then running: those are run again one at a time in a pool of their
    own, so the one that dies again gets a row saying so (status "error", kept in the
    checkpoint, not run again on resume) and the others their results; the rest go on. A
    Ctrl-C cancels the queued cases and stops the workers at once (the finished rows are
    in the checkpoint already) and is raised again."""
    mech, cases, t_end, metrics, run_options = args
    pool = ProcessPoolExecutor(max_workers=n)
    pending = {pool.submit(run_case, mech, cases[i], t_end, metrics, run_options): i
               for i in todo}
    broken: list[int] = []
    try:
        while pending:
            fin, _ = wait(pending, return_when=FIRST_COMPLETED)
            for fut in fin:
                i = pending.pop(fut)
                try:
                    finish(i, fut.result())
                except BrokenProcessPool:
                    broken.append(i)
    except KeyboardInterrupt:
        procs = list((getattr(pool, "_processes", None) or {}).values())
        pool.shutdown(wait=False, cancel_futures=True)
        for proc in procs:  # the cases already running are not waited for either
            proc.terminate()
        raise
    pool.shutdown(wait=True)
    if broken == todo and n == 1:  # alone in its pool, and it died again: it kills it
        finish(todo[0], {**cases[todo[0]], "status": "error",
                         "message": "the worker process running this case died (a crash "
                                    "or out of memory)", "t_reached": math.nan})
        return
    for i in broken:  # one at a time, to find the one that kills its worker
        _run_pool([i], 1, args, finish)


def parse_range(spec: str) -> tuple[str, list[float]]:
    """``path=a:b:n`` (n values from a to b), ``path=v1,v2,...`` or ``path=v``."""
    if "=" not in spec:
        raise ModelError(Problem("sweep", "--param", f"expected PATH=A:B:N or PATH=V1,V2; "
                                 f"got {spec!r}"))
    path, rhs = spec.split("=", 1)
    try:
        if ":" in rhs:
            a, b, n = rhs.split(":")
            lo, hi, count = float(a), float(b), int(n)
        else:
            values = [float(v) for v in rhs.split(",")]
            count = len(values)
    except ValueError:
        raise ModelError(Problem("sweep", path, f"expected A:B:N or V1,V2,...; got {rhs!r}")
                         ) from None
    if not 1 <= count <= MAX_CASES:
        raise ModelError(Problem("sweep", path, f"expected 1 to {MAX_CASES} values, "
                                 f"got {count}"))
    if ":" in rhs:
        values = list(np.linspace(lo, hi, count))
    return path, values
