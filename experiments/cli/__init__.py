"""The `terrabench` command line: one module per subcommand, each with add_arguments, run and run_from_args.

Every user error (a TerrabenchError, from an option check or from the library) ends with the one line
`terrabench: error: ...` naming the argument and exit code 2, before anything is written; any other
exception is a bug and keeps its traceback.
"""

from __future__ import annotations

import argparse
import os
import sys
import warnings

from hybrid.errors import TerrabenchError

from . import bench, calibrate, info, prepare, render, report, run, scale, stress

COMMANDS = {
    "info": info,
    "render": render,
    "run": run,
    "report": report,
    "calibrate": calibrate,
    "stress": stress,
    "bench": bench,
    "prepare": prepare,
    "scale": scale,
}
"""Subcommand name -> its module."""


class _Parser(argparse.ArgumentParser):
    """argparse's own usage errors (unknown option, bad choice) as one error line and exit code 2."""

    def error(self, message):
        self.print_usage(sys.stderr)
        print(f"{self.prog}: error: {message}", file=sys.stderr)
        raise SystemExit(2)


def build_parser() -> argparse.ArgumentParser:
    """The argument parser with every subcommand."""
    p = _Parser(
        prog="terrabench",
        description="Rasterize meshes or ray-cast the height field, tile by tile: "
        "render, measure and compare on real elevation data.",
    )
    p.add_argument("--device", type=int, default=None, help="EGL device index (or TERRABENCH_GL_DEVICE)")
    sub = p.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)
    for name, module in COMMANDS.items():
        sp = sub.add_parser(name, help=module.HELP)
        module.add_arguments(sp)
        sp.set_defaults(func=module.run_from_args)
    return p


def main(argv=None) -> int:
    """Run the command line; returns the exit code (2 for user errors)."""
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
        if not args.command:
            parser.print_help()
            return 2
        with warnings.catch_warnings():
            warnings.simplefilter("default")
            return int(args.func(args) or 0)
    except TerrabenchError as exc:
        print(f"terrabench: error: {exc}", file=sys.stderr)
        return 2
    except BrokenPipeError:  # the reader of stdout went away (| head): stop quietly
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())  # so the interpreter's final flush does not fail again
        return 141
