# SPDX-License-Identifier: Apache-2.0
"""The ``qpretarget`` command line: subcommands are discovered from :mod:`qpretarget.commands`."""

from __future__ import annotations

import argparse
import sys

from .errors import QPRetargetError

EPILOG = """examples:
  qpretarget demo                                  retarget the built-in motion on G1
  qpretarget info configs/g1_augmentation.yaml     robot, DoF, frames, limits of a config
  qpretarget bench configs/g1_augmentation.yaml    ticks per second
  qpretarget <command> --help                      help and examples of one command
"""


def build_parser() -> argparse.ArgumentParser:
    """The argument parser with every discovered subcommand."""
    from . import __version__
    from .commands import discover

    parser = argparse.ArgumentParser(
        prog="qpretarget",
        description="Online human-to-humanoid motion retargeting as a QP whole-body controller.",
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("--version", action="version", version=f"qpretarget {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for mod in discover():
        mod.register(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Run the command line; return the exit code.

    0: done; 1: a user error (bad input, config or path), printed as one clear line; 2: a usage
    error (argparse prints the usage line and the error); 130: interrupted (Ctrl-C).
    """
    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "func", None):
        parser.print_help()
        return 1
    try:
        return int(args.func(args) or 0)
    except QPRetargetError as exc:
        print(f"qpretarget {args.command}: error: {exc}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print(f"qpretarget {args.command}: interrupted.", file=sys.stderr)
        return 130
    except BrokenPipeError:
        # The reader went away (`qpretarget info g1 | head`): not an error of ours. Point stdout
        # at /dev/null so the interpreter's final flush does not raise again.
        import os

        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        return 0
    except OSError as exc:
        # A file the system refused (an output under /proc, a full disk, ...): one line that
        # names the file, not a traceback.
        where = f" {exc.filename!r}" if exc.filename else ""
        print(f"qpretarget {args.command}: error: cannot write or read{where}: "
              f"{exc.strerror or exc}.", file=sys.stderr)  # fmt: skip
        return 1


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
