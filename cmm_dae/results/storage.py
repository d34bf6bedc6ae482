"""Reading saved Results back (``Result.save`` writes them): every way a file can be wrong
ends in a :class:`CmmError` that names the file."""

from __future__ import annotations

import json
import zipfile
from pathlib import Path

import numpy as np

from ..core.errors import CmmError, Status
from .result import Configuration, Event, Result, Stats


def load_result(path: str | Path) -> Result:
    """Read a Result written by :meth:`Result.save`.

    Raises
    ------
    CmmError
        The file is missing, not a saved Result, truncated or corrupted (named, with what
        was wrong).
    """
    path = Path(path)
    try:
        with path.open("rb") as f:
            if f.read(2) != b"PK":  # every .npz is a zip archive
                raise CmmError(f"'{path}' is not a result file (not an .npz archive written "
                               "by Result.save)")
        with np.load(path, allow_pickle=False) as z:
            if "__meta__" not in z.files:
                raise CmmError(f"'{path}' is not a cmm_dae result file (no '__meta__' entry; "
                               "write one with Result.save)")
            meta = json.loads(str(z["__meta__"]))
            data = {k: np.asarray(z[k]) for k in z.files if k != "__meta__"}
        configs = [Configuration(tuple(c["locked"]), tuple(c["sides"]), int(c["dof"]),
                                 str(c["label"]), tuple(c.get("zones", ())),
                                 tuple((j, int(s)) for j, s in c.get("slip", ())))
                   for c in meta.pop("configurations")]
        events = [Event(**e) for e in meta.pop("events")]
        stats = Stats(**meta.pop("stats"))
        status = meta.pop("status")
        message = meta.pop("message", status)
        try:
            status = Status(status)
        except ValueError:  # a file from before status codes: a free sentence
            message, status = status, Status.INTEGRATOR
        res = Result(meta, data, configs, events, stats, status, message)
        n = res.t.size
        # ("c" is missing only from the states a run kept when post-processing ran out
        # of memory)
        for k in ("q", "v", "config") + (("c",) if "lam" in data else ()):
            if data[k].shape[0] != n:
                raise ValueError(f"array '{k}' has {data[k].shape[0]} rows for {n} times")
        return res
    except CmmError:
        raise
    except FileNotFoundError:
        raise CmmError(f"no such result file: '{path}'") from None
    except OSError as e:
        raise CmmError(f"cannot read result file '{path}': {e.strerror or e}") from None
    except (zipfile.BadZipFile, EOFError) as e:
        raise CmmError(f"'{path}' is truncated or not a result file ({e})") from None
    except (KeyError, TypeError, ValueError, AttributeError, RecursionError) as e:
        raise CmmError(f"'{path}' is a corrupted result file ({type(e).__name__}: {e})"
                       ) from None

