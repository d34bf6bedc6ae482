"""The reference sections of the docs are generated into the repository (docs/generate.py):
they must be current, so that the files read on the repository host are the reference."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def test_generated_reference_sections_are_current():
    r = subprocess.run([sys.executable, str(ROOT / "docs" / "generate.py"), "--check"],
                       capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stdout + r.stderr


def test_the_reference_is_in_the_files_not_placeholders():
    api = (ROOT / "docs" / "api.md").read_text()
    assert "### `simulate`" in api and "```python\nsimulate(" in api
    assert "Raises" in api  # docstrings, not directives only
    assert "### `cmm-dae run`" in (ROOT / "docs" / "cli.md").read_text()
    assert "joints" in (ROOT / "docs" / "model-file.md").read_text().split(
        "<!-- generated: model-file -->")[1]
