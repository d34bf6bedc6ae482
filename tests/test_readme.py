"""The README's Python tour runs as written (from a directory holding the models)."""

from __future__ import annotations

import os
import re
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def test_readme_python_tour_runs(tmp_path, monkeypatch):
    text = (ROOT / "README.md").read_text()
    blocks = re.findall(r"```python\n(.*?)```", text, re.S)
    assert blocks
    os.symlink(ROOT / "models", tmp_path / "models")
    monkeypatch.chdir(tmp_path)
    scope: dict = {}
    for block in blocks:
        exec(compile(block, "README.md", "exec"), scope)  # noqa: S102 - our own README
    assert scope["res"].success and len(scope["res"].events) == 2
    assert (tmp_path / "out.csv").stat().st_size > 0 and (tmp_path / "sweep.csv").is_file()
    assert [e.kind for e in scope["r"].events][:2] == ["stick", "slip"]
