"""The shipped example models, found by name.

In an installed package they lie in ``cmm_dae/examples``; in a source checkout, in the
repository's ``models/`` folder (the same files: the wheel installs ``models/`` as
``cmm_dae/examples``).
"""

from __future__ import annotations

import difflib
from pathlib import Path

from .errors import CmmError

_HERE = Path(__file__).resolve().parent


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
    if path.exists() or path.suffix or "/" in arg or "\\" in arg:
        return path  # a path (the loader says clearly if it cannot be read)
    return example(arg)
