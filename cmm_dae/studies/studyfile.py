"""Design study files (TOML) for ``cmm-dae design``."""

from __future__ import annotations

import tomllib
from pathlib import Path
from typing import Any

from ..core.errors import ModelError, Problem
from ..description.library import model_path
from ..description.loader import load
from .design import Design, design

__all__ = ["design_spec"]


_SPEC_KEYS = {"model", "t_end", "objective", "driver", "method", "max_iter", "out", "run",
              "params", "targets"}


def design_spec(path: str | Path) -> dict[str, Any]:
    """Read a design study file (TOML)::

        model = "double_folded"          # a model file (relative to this file) or example
        t_end = 10.0                     # s
        objective = "peak_effort"        # the peak |effort| of `driver` (default: first)
        method = "SLSQP"                 # or "trust-constr"
        out = "design_report"            # report directory (relative to this file)
        [run]                            # options of each run
        rtol = 1e-10
        [[params]]
        path = "joints.D.spring.stiffness"
        bounds = [0.5, 2.0]
        [[targets]]
        event = "limit E"
        value = 2.5

    Returns a dict with ``out`` (Path) and ``run_design`` (a callable running the study).

    Raises
    ------
    ModelError
        The file cannot be read, or a key is missing or wrong (file, table and key named).
    """

    path = Path(path)
    src = str(path)
    try:
        data = tomllib.loads(path.read_text(encoding="utf-8"))
    except OSError as e:
        raise ModelError(Problem("", "", f"cannot read the file: {e.strerror or e}"),
                         src) from None
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as e:
        raise ModelError(Problem("", "", f"not a TOML file: {e}"), src) from None
    bad = [Problem("", k, f"unknown key; expected {', '.join(sorted(_SPEC_KEYS))}")
           for k in data if k not in _SPEC_KEYS]
    for k in ("model", "params"):
        if k not in data:
            bad.append(Problem("", k, "missing"))
    params = data.get("params", [])
    if not isinstance(params, list) or not all(isinstance(p, dict) for p in params):
        bad.append(Problem("params", "", "expected [[params]] tables with 'path' and "
                           "'bounds'"))
        params = []
    for i, p in enumerate(params):
        for k in ("path", "bounds"):
            if k not in p:
                bad.append(Problem(f"params[{i}]", k, "missing"))
        extra = set(p) - {"path", "bounds"}
        if extra:
            bad.append(Problem(f"params[{i}]", ", ".join(sorted(extra)), "unknown key; "
                               "expected path, bounds"))
    run = data.get("run", {})
    if not isinstance(run, dict):
        bad.append(Problem("run", "", "expected a table of run options (rtol, atol, ...)"))
    targets = data.get("targets", [])
    if not isinstance(targets, list):
        bad.append(Problem("targets", "", "expected [[targets]] tables"))
    t_end = data.get("t_end", 10.0)
    if isinstance(t_end, bool) or not isinstance(t_end, int | float) or t_end <= 0:
        bad.append(Problem("", "t_end", f"expected a positive end time in s, got {t_end!r}"))
    if bad:
        raise ModelError(bad, src)
    model = str(data["model"])
    rel = path.parent / model
    mech = load(rel if rel.suffix == ".toml" and rel.is_file() else model_path(model))
    out = path.parent / str(data.get("out", "design_report"))

    def run_design() -> Design:
        try:
            return design(mech, [p["path"] for p in params],
                          [tuple(p["bounds"]) for p in params],
                          data.get("objective", "peak_effort"), targets, float(t_end),
                          driver=data.get("driver"), method=data.get("method", "SLSQP"),
                          max_iter=int(data.get("max_iter", 50)), **run)
        except ModelError as e:  # the study file's keys, named in it
            raise ModelError(e.problems, src) from None

    return {"out": out, "run_design": run_design}
