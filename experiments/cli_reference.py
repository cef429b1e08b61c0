"""The command-line reference (docs/cli.md), generated from the argparse parsers of ``experiments.cli``.

    python -m experiments.cli_reference > docs/cli.md

The text is built from the parsers' actions (flags, metavars, choices, defaults, help), not from ``--help``'s
wrapped layout, so it does not depend on the terminal's width or on the Python version's help formatter.
``tests/test_docs.py`` regenerates it and compares it with the committed file.
"""

from __future__ import annotations

import argparse
import contextlib
import sys

HEADER = """# Command-line reference

Generated from the argparse parsers by `python -m experiments.cli_reference > docs/cli.md`; do not edit by
hand (`tests/test_docs.py` fails when `--help` changes and this file is not regenerated). `terrabench` and
`python -m experiments` are the same command. Every user error ends with one line `terrabench: error: ...`
and exit code 2, before anything is written.
"""


def _cell(text: str) -> str:
    """Text fit for one Markdown table cell."""
    return " ".join(str(text).split()).replace("|", "\\|")


def _value(action: argparse.Action) -> str:
    """What an option takes: its choices, its metavar, or nothing for a flag."""
    if action.nargs == 0:
        return ""
    if action.choices is not None:
        return "{" + ",".join(str(c) for c in action.choices) + "}"
    if action.metavar is not None:
        return str(action.metavar)
    return action.dest.upper() if action.option_strings else action.dest


def _usage(action: argparse.Action) -> str:
    """A positional argument as the usage line shows it."""
    v = _value(action)
    return {"?": f"[{v}]", "*": f"[{v} ...]", "+": f"{v} [{v} ...]"}.get(str(action.nargs), v)


def _default(action: argparse.Action) -> str:
    """The default, where it says something (not for flags, help or required arguments)."""
    if action.nargs == 0 or action.required or action.default in (None, argparse.SUPPRESS):
        return ""
    return f"`{action.default}`"


def _help(action: argparse.Action) -> str:
    """The action's help with argparse's %-placeholders filled in."""
    text = action.help or ""
    if "%" in text:
        params = {**vars(action), "prog": "terrabench"}
        params = {k: getattr(v, "__name__", v) for k, v in params.items()}
        with contextlib.suppress(KeyError, TypeError, ValueError):  # a literal % stays as written
            text = text % params
    return text


def _table(actions: list[argparse.Action]) -> list[str]:
    """A Markdown table of arguments: name, value, default, meaning."""
    rows = ["| argument | value | default | meaning |", "|---|---|---|---|"]
    for a in actions:
        name = ", ".join(f"`{s}`" for s in a.option_strings) if a.option_strings else f"`{a.dest}`"
        if a.option_strings and a.required:
            name += " (required)"
        value = _value(a)
        rows.append(
            f"| {name} | {_cell(value) and '`' + _cell(value) + '`'} | {_cell(_default(a))} | {_cell(_help(a))} |"
        )
    return rows


def _arguments(parser: argparse.ArgumentParser) -> list[argparse.Action]:
    """A parser's arguments, help and subcommand actions left out."""
    return [
        a
        for a in parser._actions
        if not isinstance(a, (argparse._HelpAction, argparse._SubParsersAction)) and a.help != argparse.SUPPRESS
    ]


def reference() -> str:
    """The whole reference as Markdown."""
    from experiments.cli import build_parser

    parser = build_parser()
    out = [
        HEADER,
        "## terrabench",
        "",
        _cell(parser.description or ""),
        "",
        "Global options (before the subcommand):",
        "",
        *_table(_arguments(parser)),
        "",
        "Subcommands:",
        "",
    ]
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    helps = {c.dest: c.help for c in sub._choices_actions}
    for name in sub.choices:
        out.append(f"- [`{name}`](#terrabench-{name}): {_cell(helps.get(name) or '')}")
    out.append("")
    for name, sp in sub.choices.items():
        out += [f"## terrabench {name}", "", _cell(helps.get(name) or ""), ""]
        if sp.description:
            out += [_cell(sp.description), ""]
        args = _arguments(sp)
        positional = [a for a in args if not a.option_strings]
        options = [a for a in args if a.option_strings]
        out += ["```", " ".join(["terrabench", name, *(_usage(a) for a in positional), "[options]"]), "```", ""]
        out += _table(positional + options) if args else ["No arguments."]
        out.append("")
    return "\n".join(out)


def main() -> int:
    """Print the reference."""
    sys.stdout.write(reference())
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
