"""A Result as named columns, CSV, a pandas DataFrame, or an ``.npz`` file."""

from __future__ import annotations

import csv
import json
from dataclasses import asdict
from pathlib import Path
from typing import Any

import numpy as np

from ..core.errors import CmmError

# ``res`` below is a cmm_dae.Result; not imported, so that result (which calls these
# functions) and export do not import each other.
Result = Any


def columns(res: Result) -> dict[str, np.ndarray]:
    """Every series of ``res`` as named columns, SI units in the names.

    ``configuration`` holds each sample's configuration as text (``"E locked (upper)"``,
    ``"all free"``, ...) and ``configuration index`` its index in ``res.configurations``.
    """
    labels = np.array([c.describe() for c in res.configurations], dtype=object)
    cols: dict[str, np.ndarray] = {"t [s]": res.t,
                                   "configuration": labels[res.configuration],
                                   "configuration index": res.configuration}
    lay = res.layout
    spatial = lay.space == "spatial"
    parts = lay.joint_components()
    for name in lay.joints:
        u = lay.coordinate_unit(name)
        js = res.joint(name)
        cols[f"joint {name} position [{u}]"] = js.position
        cols[f"joint {name} velocity [{u}/s]"] = js.velocity
        cols[f"joint {name} acceleration [{u}/s^2]"] = js.acceleration
        for lab, unit, get in parts:
            cols[f"joint {name} {lab} [{unit}]"] = get(js)
    for name in lay.drivers:
        u = "N m" if lay.coordinate_unit(name) == "rad" else "N"
        cols[f"driver {name} effort [{u}]"] = res.driver(name).effort
    pose = (("x [m]", "y [m]", "z [m]", "qw", "qx", "qy", "qz") if spatial
            else ("x [m]", "y [m]", "theta [rad]"))
    for name in lay.bodies:
        b = res.body(name)
        for k, lab in enumerate(pose):
            cols[f"body {name} {lab}"] = b.pose[:, k]
    return cols


def to_csv(res: Result, path: str | Path) -> Path:
    """Write :func:`columns` to ``path``: a header row, then one row per sample (numbers
    written with ``repr``, so they read back to the bit)."""
    path = Path(path)
    cols = columns(res)
    with path.open("w", newline="") as f:
        w = csv.writer(f)
        w.writerow(list(cols))
        for row in zip(*cols.values(), strict=True):
            w.writerow([x if isinstance(x, str) else repr(float(x)) for x in row])
    return path


def to_dataframe(res: Result) -> Any:
    """:func:`columns` as a :class:`pandas.DataFrame` (``configuration`` categorical)."""
    try:
        import pandas as pd
    except ImportError:
        raise CmmError("Result.to_dataframe needs pandas: pip install 'cmm_dae[dataframe]'"
                       ) from None
    df = pd.DataFrame(columns(res))
    df["configuration"] = pd.Categorical(
        df["configuration"], categories=list(dict.fromkeys(c.describe()
                                                           for c in res.configurations)))
    return df


def save(res: Result, path: str | Path) -> Path:
    """Save the whole Result (arrays, configurations, events, stats) to an ``.npz`` file
    (read back with :func:`cmm_dae.load_result`)."""
    path = Path(path)
    meta = dict(res.meta)
    meta["configurations"] = [asdict(c) for c in res.configurations]
    meta["events"] = [asdict(e) for e in res.events]
    meta["stats"] = asdict(res.stats)
    meta["status"] = str(res.status)
    meta["message"] = res.message
    with path.open("wb") as f:
        np.savez_compressed(f, __meta__=np.array(json.dumps(meta)), **res.data)
    return path
