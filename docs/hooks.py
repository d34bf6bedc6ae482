"""MkDocs hook: pages generated from the package itself, so the docs cannot drift from it.

* ``<!-- model-file-reference -->`` becomes the model-file reference, written from the same
  description (``cmm_dae.description.schema.SPEC``) the loader and the JSON Schema use;
* ``<!-- cli-reference -->`` becomes the help of every ``cmm-dae`` command;
* ``<!-- changelog -->`` becomes CHANGELOG.md.
"""

from __future__ import annotations

import argparse
from pathlib import Path


def _cli_reference() -> str:
    from cmm_dae.cli import build_parser

    parser = build_parser()
    out = ["```text", parser.format_help().rstrip(), "```", ""]
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    for name, p in sub.choices.items():
        out += [f"## `cmm-dae {name}`", "", "```text", p.format_help().rstrip(), "```", ""]
    return "\n".join(out)


def on_page_markdown(markdown: str, page, config, files) -> str:
    if "<!-- model-file-reference -->" in markdown:
        from cmm_dae.description.schema import reference_markdown

        markdown = markdown.replace("<!-- model-file-reference -->", reference_markdown())
    if "<!-- cli-reference -->" in markdown:
        markdown = markdown.replace("<!-- cli-reference -->", _cli_reference())
    if "<!-- changelog -->" in markdown:
        root = Path(config["config_file_path"]).parent
        text = (root / "CHANGELOG.md").read_text()
        markdown = markdown.replace("<!-- changelog -->", text.split("\n", 1)[1])
    return markdown
