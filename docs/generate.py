"""Write the generated reference sections into the docs, so that the Markdown files read on
the repository host are the whole reference, not placeholders.

Each generated section sits between two markers and is rewritten from the package itself:

* ``<!-- generated: model-file -->`` .. ``<!-- /generated -->`` (docs/model-file.md): the
  model-file reference, from the description the loader and the JSON Schema use;
* ``<!-- generated: cli -->`` (docs/cli.md): the help of every ``cmm-dae`` command;
* ``<!-- generated: api NAME NAME ... -->`` (docs/api.md): each named object's signature and
  docstring (the site renders the same names with mkdocstrings: docs/hooks.py).

Usage, from the repository's root::

    python docs/generate.py           # rewrite the sections
    python docs/generate.py --check   # exit 1, naming the files, where one is out of date

The test suite runs the check (tests/test_docs.py), so CI fails on a stale reference.
"""

from __future__ import annotations

import argparse
import importlib
import inspect
import re
import sys
from pathlib import Path

DOCS = Path(__file__).resolve().parent
FILES = ("model-file.md", "cli.md", "api.md")
BLOCK = re.compile(r"(<!-- generated: ([^>]*?) -->\n)(.*?)(<!-- /generated -->)", re.S)


def _option_rows(parser: argparse.ArgumentParser) -> list[str]:
    rows = ["| argument | meaning |", "|---|---|"]
    for act in parser._actions:
        if isinstance(act, argparse._HelpAction | argparse._SubParsersAction):
            continue
        names = ", ".join(act.option_strings) or act.dest
        if act.option_strings and act.nargs != 0:
            names += f" {act.metavar or act.dest.upper()}"
        text = (act.help or "").replace("|", "\\|").replace("%%", "%")
        if act.choices and not isinstance(act.choices, dict):
            text += f" (one of: {', '.join(map(str, act.choices))})"
        rows.append(f"| `{names}` | {text} |")
    return rows


def cli_reference() -> str:
    """Every ``cmm-dae`` command with its arguments, as Markdown tables (built from the
    parser itself, not its help text, which differs between Python versions)."""
    from cmm_dae.cli import build_parser

    parser = build_parser()
    out = []
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    helps = {c.dest: c.help for c in sub._choices_actions}
    for name, p in sub.choices.items():
        out += [f"### `cmm-dae {name}`", "", helps.get(name) or "", "", *_option_rows(p), ""]
    return "\n".join(out)


def _obj(path: str):
    module, _, name = path.rpartition(".")
    try:
        return getattr(importlib.import_module(module), name)
    except (ImportError, AttributeError):  # a name of the package's top level
        return getattr(importlib.import_module("cmm_dae"), name)


def _signature(name: str, obj) -> str:
    try:
        sig = str(inspect.signature(obj))
    except (TypeError, ValueError):
        return ""
    return f"```python\n{name}{sig}\n```\n\n"


def _text(doc: str) -> str:
    """A docstring as it reads in the source (numpydoc sections would be Markdown
    headings and its indented parameter lines code blocks)."""
    return f"```text\n{doc.strip()}\n```\n\n"


def api_entry(path: str) -> str:
    """One object's entry: heading, signature, docstring; for a class its public methods and
    properties (their signatures and docstrings) too."""
    obj = _obj(path)
    short = path.split(".")[-1]
    out = [f"### `{short}`\n\n"]
    if inspect.isclass(obj) or inspect.isroutine(obj):
        out.append(_signature(short, obj))
    else:
        out.append(f"```python\n{short} = {obj!r}\n```\n\n")
    doc = inspect.getdoc(obj) if (inspect.isclass(obj) or inspect.isroutine(obj)) else None
    if doc:
        out.append(_text(doc))
    if inspect.isclass(obj) and not issubclass(obj, BaseException):
        for name, member in sorted(vars(obj).items()):
            if name.startswith("_") or not (inspect.isfunction(member)
                                            or isinstance(member, property | classmethod
                                                          | staticmethod)):
                continue
            fn = member.fget if isinstance(member, property) else getattr(obj, name)
            mdoc = inspect.getdoc(fn)
            if not mdoc:
                continue
            sig = "" if isinstance(member, property) else _signature(f"{short}.{name}", fn)
            out.append(f"#### `{short}.{name}`\n\n{sig}{_text(mdoc)}")
    return "".join(out)


def section(what: str) -> str:
    """The text of the generated section ``what`` ("model-file", "cli", "api NAME ...")."""
    kind, *names = what.split()
    if kind == "model-file":
        from cmm_dae.description.schema import reference_markdown

        return reference_markdown().rstrip() + "\n"
    if kind == "cli":
        return cli_reference()
    if kind == "api":
        return "".join(api_entry(n) for n in names)
    raise ValueError(f"unknown generated section {what!r}")


def regenerate(text: str) -> str:
    """``text`` with every generated section rewritten."""
    return BLOCK.sub(lambda m: m.group(1) + section(m.group(2)) + m.group(4), text)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--check", action="store_true",
                    help="only tell which files are out of date (exit 1 if any)")
    args = ap.parse_args(argv)
    stale = []
    for name in FILES:
        path = DOCS / name
        old = path.read_text()
        new = regenerate(old)
        if new != old:
            stale.append(name)
            if not args.check:
                path.write_text(new)
    if args.check and stale:
        print(f"out of date: {', '.join(stale)} (run: python docs/generate.py)")
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
