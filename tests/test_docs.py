"""The documentation runs as written: the tutorial (its TOML blocks make the model file,
its Python blocks run in order) and the getting-started tour; the numbers the tutorial
states are the numbers the code gives."""

from __future__ import annotations

import os
import re
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parent.parent
DOCS = ROOT / "docs"


def _blocks(page: str, lang: str) -> list[str]:
    return re.findall(rf"```{lang}\n(.*?)```", (DOCS / page).read_text(), re.S)


def _run(page: str, scope: dict) -> dict:
    for block in _blocks(page, "python"):
        exec(compile(block, page, "exec"), scope)  # noqa: S102 - our own documentation
    return scope


@pytest.fixture
def in_tmp(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    return tmp_path


def test_tutorial_runs_and_says_what_the_code_gives(in_tmp):
    (in_tmp / "press.toml").write_text("\n".join(_blocks("tutorial.md", "toml")))
    s = _run("tutorial.md", {})
    res, ref, text = s["res"], s["ref"], (DOCS / "tutorial.md").read_text()
    kinds = s["kinds"]
    assert kinds[:4] == [("lock", "T", "upper"), ("zone", "rail", "enter"),
                         ("release", "T", "upper"), ("limit", "T", "lower")]
    assert ("stick", "T", "stick") in kinds and kinds[-1] == ("limit", "T", "upper")
    ev = res.events
    assert f"{ev[1].t:.4f}" == "0.3325" and ev[2].t == ev[1].t
    assert f"{ev[3].t:.4f}" == "0.3730" and f"{-ev[3].velocity_before:.3f}" == "0.730"
    stick = next(e for e in ev if e.kind == "stick")
    leave = next(e for e in ev if e.kind == "zone" and e.side == "leave")
    assert stick.t < leave.t and f"{leave.t:.4f}" == "0.6675"
    for claim in ("0.3325 s", "0.3730 s with 0.73 m/s", "0.6675 s", "0.80 m/s", "0.730 m/s",
                  "0.740 m/s"):
        assert claim in text
    v_it = next(e for e in ref.events if e.kind == "limit").velocity_before
    assert f"{-v_it:.2f}" == "0.80"
    # stuck, the slide never carries more than its static level (3 N)
    calm = res.away_from_events(res.t, 1e-9)
    assert np.max(np.abs(res.joint("T").friction[calm])) <= 3.0
    assert (in_tmp / "out/press/report.html").is_file()
    rows = {r["joints.T.spring.rest"]: r for r in s["table"].rows}
    assert "t_release_T_1" not in rows[0.04] or not rows[0.04]["t_release_T_1"]
    assert rows[0.01]["t_release_T_1"] == pytest.approx(ev[2].t, abs=1e-6)


def test_getting_started_tour_runs(in_tmp):
    s = _run("getting-started.md", {})
    assert s["res"].success and len(s["res"].events) == 2
    assert s["force_E"].shape == (s["res"].t.size, 2)


def test_docs_refer_to_nothing_outside_the_repository():
    for path in [*DOCS.glob("*.md"), ROOT / "README.md", ROOT / "mkdocs.yml"]:
        text = path.read_text()
        assert "../shared" not in text and "shared/" not in text, path
    for link in re.findall(r"\]\(([^)#]+)\)", "".join(p.read_text() for p in DOCS.glob("*.md"))):
        if not link.startswith("http"):
            assert (DOCS / link).exists(), link


def test_model_reference_placeholder_is_filled_by_the_hook():
    import importlib.util

    spec = importlib.util.spec_from_file_location("hooks", DOCS / "hooks.py")
    hooks = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(hooks)
    cfg = {"config_file_path": os.fspath(ROOT / "mkdocs.yml")}
    out = hooks.on_page_markdown((DOCS / "model-file.md").read_text(), None, cfg, None)
    assert "<!--" not in out and "| `inertia_about` |" in out
    cli = hooks.on_page_markdown((DOCS / "cli.md").read_text(), None, cfg, None)
    assert "## `cmm-dae compare`" in cli and "--progress" in cli
