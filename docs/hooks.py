"""MkDocs hook: the site's pages from the Markdown files as the repository holds them.

The reference sections are generated into the files themselves (docs/generate.py; the
test suite checks they are current). On the site, the API sections are rendered by
mkdocstrings from the same names instead of the plain text (``::: NAME`` directives), and
``<!-- changelog -->`` becomes CHANGELOG.md.
"""

from __future__ import annotations

import re
from pathlib import Path

_API = re.compile(r"<!-- generated: api ([^>]*?) -->\n.*?<!-- /generated -->", re.S)


def on_page_markdown(markdown: str, page, config, files) -> str:
    markdown = _API.sub(lambda m: "\n\n".join(f"::: {n}" for n in m.group(1).split()),
                        markdown)
    if "<!-- changelog -->" in markdown:
        root = Path(config["config_file_path"]).parent
        text = (root / "CHANGELOG.md").read_text()
        markdown = markdown.replace("<!-- changelog -->", text.split("\n", 1)[1])
    return markdown
