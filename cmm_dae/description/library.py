"""The shipped example models, found by name.

In an installed package they lie in ``cmm_dae/examples``; in a source checkout, in the
repository's ``models/`` folder (the same files: the wheel installs ``models/`` as
``cmm_dae/examples``).
"""

from __future__ import annotations

import difflib
import math
from pathlib import Path

from ..core.errors import CmmError
from . import mechanism as cd
from .mechanism import Mechanism

_HERE = Path(__file__).resolve().parent.parent  # the package root


def examples_dir() -> Path:
    """Folder holding the shipped example model files."""
    for d in (_HERE / "examples", _HERE.parent / "models"):
        if d.is_dir() and any(d.glob("*.toml")):
            return d
    raise CmmError("the shipped example models are missing from this installation "
                   f"(looked in {_HERE / 'examples'} and {_HERE.parent / 'models'})")


def examples() -> list[str]:
    """Names of the shipped example models (``cd.example(name)`` gives the file)."""
    return sorted(p.stem for p in examples_dir().glob("*.toml"))


def example(name: str) -> Path:
    """Path of a shipped example model file.

    Parameters
    ----------
    name : str
        Its name, e.g. ``"double_folded"`` (with or without ``.toml``).

    Returns
    -------
    Path
        The TOML file; read it with ``cd.load(cd.example(name))``.

    Raises
    ------
    CmmError
        For an unknown name, listing the names there are.
    """
    stem = name.removesuffix(".toml")
    path = examples_dir() / f"{stem}.toml"
    if stem and "/" not in stem and path.is_file():
        return path
    names = examples()
    close = difflib.get_close_matches(stem, names, n=1)
    hint = f"; did you mean '{close[0]}'?" if close else ""
    raise CmmError(f"no example model named '{name}'{hint} (examples: {', '.join(names)})")


def model_path(arg: str) -> Path:
    """A model argument of the command line: an existing file, else an example's name."""
    path = Path(arg)
    if not path.exists() and path.suffix == ".toml" and "/" not in arg and "\\" not in arg \
            and path.stem in examples():
        # a shipped example's file name typed where no such file is (the README lists the
        # examples as files): the name alone finds it
        raise CmmError(f"no file '{arg}' here; the shipped example is run by its name alone: "
                       f"'{path.stem}'")
    if path.exists() or path.suffix or "/" in arg or "\\" in arg:
        return path  # a path (the loader says clearly if it cannot be read)
    return example(arg)


def four_bar_chain(n: int, *, driven: bool = False, swing: float = 0.3) -> Mechanism:
    """A chain of ``n`` four-bar loops hanging under gravity, built in Python.

    Ground pivots at x = 0, 1, ..., n; ``n + 1`` rockers hanging down with alternating
    lengths 0.8 and 1.0 m (so no loop is a parallelogram and the constraints stay
    independent), their tips joined by ``n`` couplers. One degree of freedom: the first
    rocker swings from rest at ``swing`` rad from the vertical (or, ``driven``, turns at
    0.5 rad/s). Uniform bars: mass 1 kg per m, centroid mid-length. A mechanism whose
    size grows with ``n`` (3 (2n + 1) coordinates, 2 (3n + 1) constraint rows), for
    scaling studies (``validation/benchmark.py``).
    """
    lengths = [0.8 if i % 2 == 0 else 1.0 for i in range(n + 1)]
    bodies, joints = [], []
    ground = {f"O{i}": (float(i), 0.0) for i in range(n + 1)}
    for i, L in enumerate(lengths):
        bodies.append(cd.Body(f"r{i}", L, L**3 / 12, (L / 2, 0.0), {"O": (0.0, 0.0),
                                                                   "T": (L, 0.0)},
                              guess=(float(i), 0.0, -math.pi / 2)))
        joints.append(cd.Joint(f"O{i}", "revolute", f"ground.O{i}", f"r{i}.O"))
    for i in range(n):
        dy = lengths[i] - lengths[i + 1]
        Lc = math.hypot(1.0, dy)
        bodies.append(cd.Body(f"c{i}", Lc, Lc**3 / 12, (Lc / 2, 0.0),
                              {"A": (0.0, 0.0), "B": (Lc, 0.0)},
                              guess=(float(i), -lengths[i], math.atan2(dy, 1.0))))
        joints.append(cd.Joint(f"A{i}", "revolute", f"r{i}.T", f"c{i}.A"))
        joints.append(cd.Joint(f"B{i}", "revolute", f"c{i}.B", f"r{i + 1}.T"))
    drivers = [cd.Driver("O0", "constant_speed", initial=-math.pi / 2, speed=0.5)] if driven \
        else []
    ini = cd.Initial({} if driven else {"O0": -math.pi / 2 + swing})
    return cd.Mechanism(name=f"chain of {n} four-bar loops", bodies=bodies, joints=joints,
                        ground=ground, drivers=drivers, initial=ini)
