"""The ``demcal`` command. Each stage registers its own sub-commands in its ``cli`` module;
this dispatcher turns every domain error into a one-line message on stderr and a non-zero exit."""

from __future__ import annotations

import argparse
import importlib
import sys

from demcal import __version__
from demcal.errors import DemcalError
from demcal.text import one_line

#: Stage modules that contribute sub-commands, in the order of the pipeline.
STAGE_CLIS = ("demcal.measure.cli", "demcal.measure.repose_cli", "demcal.simulate.cli",
              "demcal.simulate.virtual_lab_cli", "demcal.analyse.cli", "demcal.calibrate",
              "demcal.analyse.critique.cli", "demcal.analyse.critique.plan_cli",
              "demcal.report.cli", "demcal.export")

EXIT_INPUT = 2     # bad input or a domain error
EXIT_FAILURE = 1   # the job ran but failed a check (e.g. audit found differences)

#: Longest error message printed [characters]: long enough for any message of demcal's own.
ERROR_LIMIT = 2000


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="demcal",
        description="Calibrate DEM material models from lab measurements.")
    parser.add_argument("--version", action="version", version=f"demcal {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True
    for name in STAGE_CLIS:
        importlib.import_module(name).register(sub)
    return parser


def main(argv=None) -> int:
    try:
        parser = build_parser()
    except ModuleNotFoundError as exc:
        # a stage (or a library it needs) is missing from this installation: say which
        print(f"demcal: error: this installation lacks {exc.name!r} ({exc}); reinstall demcal "
              "with its dependencies (pip install demcal)", file=sys.stderr)
        return EXIT_FAILURE
    args = parser.parse_args(argv)
    try:
        return int(args.handler(args) or 0)
    except DemcalError as exc:
        # the message may quote workbook text: one line, whatever that text holds
        print(f"demcal {args.command}: error: {one_line(exc, limit=ERROR_LIMIT)}", file=sys.stderr)
        return EXIT_INPUT
    except FileNotFoundError as exc:
        print(f"demcal {args.command}: error: file not found: {one_line(exc.filename, limit=ERROR_LIMIT)}",
              file=sys.stderr)
        return EXIT_INPUT
    except ModuleNotFoundError as exc:
        print(f"demcal {args.command}: error: this installation lacks {exc.name!r} ({exc}); "
              "reinstall demcal with its dependencies", file=sys.stderr)
        return EXIT_FAILURE
    except KeyboardInterrupt:
        print(f"demcal {args.command}: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
