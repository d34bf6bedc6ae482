"""Writing a mechanism with changed parameters back as a model file: the source file's
tables with the new values at their dotted paths (what a design study hands over)."""

from __future__ import annotations

import json
import math
import tomllib
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from ..core.errors import CmmError
from .mechanism import Mechanism
from .params import _point_ref, with_params

__all__ = ["dumps", "write_model"]


def _value(v: Any) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        if math.isnan(v):
            return "nan"
        if math.isinf(v):
            return "inf" if v > 0 else "-inf"
        return repr(v)
    if isinstance(v, str):
        return json.dumps(v)  # a TOML basic string (same escapes)
    if isinstance(v, list | tuple):
        return "[" + ", ".join(_value(x) for x in v) + "]"
    if isinstance(v, Mapping):
        return "{ " + ", ".join(f"{_key(k)} = {_value(x)}" for k, x in v.items()) + " }"
    raise CmmError(f"cannot write {v!r} to TOML")


def _key(k: str) -> str:
    return k if k.replace("_", "").replace("-", "").isalnum() else json.dumps(k)


def dumps(data: Mapping[str, Any]) -> str:
    """TOML text of a model-file structure: top-level tables and their named entries as
    ``[table.entry]`` sections, anything deeper as inline tables."""
    out: list[str] = []
    for k, v in data.items():
        if not isinstance(v, Mapping):
            out.append(f"{_key(k)} = {_value(v)}")
    for k, v in data.items():
        if not isinstance(v, Mapping):
            continue
        flat = {a: b for a, b in v.items() if not isinstance(b, Mapping)}
        subs = {a: b for a, b in v.items() if isinstance(b, Mapping)}
        if flat or not subs:
            out += ["", f"[{_key(k)}]"] + [f"{_key(a)} = {_value(b)}" for a, b in flat.items()]
        for a, b in subs.items():
            out += ["", f"[{_key(k)}.{_key(a)}]"] + [f"{_key(c)} = {_value(x)}"
                                                     for c, x in b.items()]
    return "\n".join(out).lstrip("\n") + "\n"


def write_model(mech: Mechanism, path: str | Path, values: Mapping[str, float], *,
                overwrite: bool = False) -> Path:
    """Write ``mech`` (loaded from a model file, with the dotted-path ``values`` changed)
    as a model file at ``path``.

    Raises
    ------
    CmmError
        ``mech`` was not loaded from a model file, or ``path`` exists and ``overwrite`` is
        False.
    ModelError
        A path that is not a parameter of the mechanism, or a value that is not a finite
        number (checked as :func:`~cmm_dae.description.params.with_params` does).
    """
    path = Path(path)
    if mech.source is None or not Path(mech.source).is_file():
        raise CmmError("the mechanism was not loaded from a model file: there is no file "
                       "to write the new values into")
    if path.exists() and not overwrite:
        raise CmmError(f"{path} exists; pass overwrite=True to replace it")
    # every value a parameter of this mechanism and a finite number, checked before the
    # file is written (it wrote unknown keys and NaN into model files)
    with_params(mech, dict(values))
    data = tomllib.loads(Path(mech.source).read_text(encoding="utf-8"))
    for p, x in values.items():
        parts = p.split(".")
        x = float(x)
        if parts[0] == "gravity":
            g = list(data.setdefault("mechanism", {}).get("gravity", list(mech.gravity)))
            g["xy".index(parts[1])] = x
            data["mechanism"]["gravity"] = g
            continue
        if _point_ref(mech, parts) is not None:
            # a point coordinate: one component of the point's [x, y]
            pts = (data["ground"] if parts[0] == "ground" else data["bodies"][parts[1]]
                   )["points"]
            xy = list(pts[parts[-2]])
            xy["xy".index(parts[-1])] = x
            pts[parts[-2]] = xy
            continue
        if parts[0] == "bodies":  # inertia in the file may be about a point: centroidal
            body = data["bodies"][parts[1]]
            body[parts[2]] = x
            if body.pop("inertia_about", None) is not None:
                body["inertia"] = float(mech.bodies[parts[1]].inertia)
            continue
        node = data
        for key in parts[:-1]:
            node = node.setdefault(key, {})
        node[parts[-1]] = x
    path.write_text(f"# {mech.name}: written by cmm_dae from {Path(mech.source).name} with "
                    f"{', '.join(values)} changed\n" + dumps(data), encoding="utf-8")
    return path
