"""The ``rtsar`` command.  ``rtsar COMMAND --help`` explains each command.

One module per command group: ``files`` (presets, simulate, process, quicklook), ``streaming``
(run, subscribe, keygen), ``replay`` (replay, demo), ``view``, ``measure`` (devices, measure, bench,
tradeoff, table1), ``formats``, ``batch``, ``swath`` (swath-worker), ``spot``; ``options``
declares the options they share; ``commands`` names them all.  A call imports only the module
of its command (``rtsar --help`` and ``--version`` none), so the command line starts at once.
"""

from __future__ import annotations

import argparse
import importlib
import sys
import warnings

from ...sinks.endpoint import DEFAULT_ENDPOINT
from ...version import version_text
from .. import signals
from .commands import COMMANDS, HELP, MODULE

EPILOG = f"""examples:
  rtsar run                                  live demo: the built-in scene streamed at its PRF,
                                             strips published on {DEFAULT_ENDPOINT}
  rtsar view --png live.png                  snapshot of the live strips (or a window)
  rtsar view --http 8080                     the live strips on a page: http://127.0.0.1:8080/
  rtsar subscribe -o live.h5                 record the published strips into an image file
  rtsar replay rec.h5 --rate max             a recording through the live pipeline
  rtsar presets                              the instrument presets and their theoretical figures
  rtsar simulate scene.toml -o rec.h5        raw shots of a scene
  rtsar process rec.h5 -o img.h5             range + azimuth compression (streaming engine)
  rtsar batch recs/ --out-dir imgs           many recordings through process, on Dask
  rtsar quicklook img.h5 -o img.png          dB image, axes in km, m, mm or µm
  rtsar bench                                lens and correlator throughput in one run
  rtsar tradeoff                             what accuracy costs in time: every knob, one run
  rtsar table1                               Psaltis & Wagner's Table 1 from the physical emulation
  rtsar spotlight --live --every 200 --publish   spotlight SAL: progressive images on topic 'spot'
  rtsar export rec.h5 --cphd rec.cphd        a recording as CPHD (also --sigmf; images: --sicd)
"""


class VersionAction(argparse.Action):
    """``--version``: asks git only when given (rtsar.version), not on every command."""

    def __init__(self, option_strings, dest, help=None):
        super().__init__(option_strings, dest, nargs=0, default=argparse.SUPPRESS, help=help)

    def __call__(self, parser, namespace, values, option_string=None):
        print(version_text())
        parser.exit()


class _Declare:
    """The subparsers of a parser as a command module's ``add_parsers`` sees them: the commands
    wanted are declared (their help line from ``commands``), the others swallowed unbuilt."""

    def __init__(self, sub, wanted):
        self.sub, self.wanted = sub, wanted

    def add_parser(self, name: str, **kw):
        if name not in self.wanted:
            return _Unbuilt()
        return self.sub.add_parser(name, help=HELP[name], **kw)


class _Unbuilt:
    """A parser (or group) declared for a command this call does not run: every call is a no-op."""

    def __getattr__(self, attr):
        return lambda *args, **kw: self


def build_parser(command: str | None = "*") -> argparse.ArgumentParser:
    """The ``rtsar`` parser: every command fully declared (``"*"``, the default), only
    ``command`` (the others listed by name and help line), or none (``None``: --help and
    --version need no command module)."""
    p = argparse.ArgumentParser(
        prog="rtsar",
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog=EPILOG,
        description="Real-time SAR/SAL image formation after Psaltis & Wagner's acousto-optic/CCD "
        "processor: an OpenCL 'AO lens' compresses each pulse in range, a shifting-"
        "CCD correlator with a chirp mask compresses in azimuth.",
    )
    p.add_argument(
        "--version",
        action=VersionAction,
        help="the release and the git commit this rtsar was installed from, then exit",
    )
    sub = p.add_subparsers(dest="command", metavar="COMMAND")
    declared = set()
    for name, module, line in COMMANDS:
        if command != "*" and name != command:
            sub.add_parser(name, help=line, add_help=False)  # listed, never parsed
            continue
        if module in declared:
            continue
        declared.add(module)
        group = importlib.import_module(f"{__name__}.{module}")
        group.add_parsers(_Declare(sub, MODULE if command == "*" else (name,)))
    return p


def _command_of(argv: list[str]) -> str | None:
    """The command a command line names: its first word that is not an option."""
    for word in argv:
        if not word.startswith("-"):
            return word if word in MODULE else None
    return None


def _show_warning(message, category, filename, lineno, file=None, line=None) -> None:
    """Warnings as one plain line on stderr (users need the message, not our source line)."""
    print(f"rtsar: warning: {message}", file=file or sys.stderr, flush=True)


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    parser = build_parser(_command_of(argv))
    args, unknown = parser.parse_known_args(argv)
    if unknown:  # said with the usage of the parser they were given to: `run --bogus` run's,
        # `--bogus run` the top level's (the words before the command are rtsar's own)
        commands = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
        at = next((i for i, word in enumerate(argv) if not word.startswith("-")), len(argv))
        own = any(word in argv[:at] for word in unknown)
        owner = parser if own else commands.choices.get(args.command or "", parser)
        owner.error(f"unrecognized arguments: {' '.join(unknown)}")
    if not getattr(args, "func", None):
        parser.print_help()
        return 0
    signals.install()
    warnings.showwarning = _show_warning
    from .options import die
    from .outputs import check_outputs_spare_inputs

    try:
        check_outputs_spare_inputs(args)
        return args.func(args)
    except BrokenPipeError:  # `rtsar presets | head`: the reader has all it wanted
        sys.stdout = None  # nothing more to flush into the closed pipe at exit
        return 0
    except (ValueError, OSError, RuntimeError) as exc:
        return die(str(exc))
    except MemoryError as exc:  # a size no check foresaw: one line, not numpy's traceback
        return die(f"not enough memory for this request ({exc or 'allocation failed'})")
    except KeyboardInterrupt as exc:
        print(f"\nrtsar: {signals.describe(exc)}", file=sys.stderr)
        return signals.exit_status(exc)


if __name__ == "__main__":
    sys.exit(main())
