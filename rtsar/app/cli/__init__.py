"""The ``rtsar`` command.  ``rtsar COMMAND --help`` explains each command.

One module per command group: ``files`` (presets, simulate, process, quicklook), ``streaming``
(run, replay, subscribe, view, keygen), ``measure`` (bench, tradeoff, table1), ``batch``,
``swath`` (swath-worker); ``options`` declares the options they share.
"""

from __future__ import annotations

import argparse
import sys
import warnings

from ...sinks.publish import DEFAULT_ENDPOINT
from ...version import version_text
from .. import signals
from . import batch, files, formats, measure, spot, streaming, swath
from .options import check_outputs_spare_inputs, die

EPILOG = f"""examples:
  rtsar run                                  live demo: the built-in scene streamed at its PRF,
                                             strips published on {DEFAULT_ENDPOINT}
  rtsar view --png live.png                  snapshot of the live strips (or a window)
  rtsar subscribe -o live.h5                 record the published strips into an image file
  rtsar replay rec.h5 --rate max             a recording through the live pipeline
  rtsar presets                              the instrument presets and their theoretical figures
  rtsar simulate scene.toml -o rec.h5        raw shots of a scene
  rtsar process rec.h5 -o img.h5             range + azimuth compression (streaming engine)
  rtsar batch recs/ --out-dir imgs           many recordings through process, on Dask
  rtsar quicklook img.h5 -o img.png          dB image with axes in metres
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


def build_parser() -> argparse.ArgumentParser:
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
    files.add_parsers(sub)
    streaming.add_parsers(sub)
    measure.add_parsers(sub)
    formats.add_parsers(sub)
    batch.add_parsers(sub)
    swath.add_parsers(sub)
    spot.add_parsers(sub)
    return p


def _show_warning(message, category, filename, lineno, file=None, line=None) -> None:
    """Warnings as one plain line on stderr (users need the message, not our source line)."""
    print(f"rtsar: warning: {message}", file=file or sys.stderr, flush=True)


def main(argv=None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "func", None):
        parser.print_help()
        return 0
    signals.install()
    warnings.showwarning = _show_warning
    try:
        check_outputs_spare_inputs(args)
        return args.func(args)
    except BrokenPipeError:  # `rtsar presets | head`: the reader has all it wanted
        sys.stdout = None  # nothing more to flush into the closed pipe at exit
        return 0
    except (ValueError, OSError, RuntimeError) as exc:
        return die(str(exc))
    except KeyboardInterrupt as exc:
        print(f"\nrtsar: {signals.describe(exc)}", file=sys.stderr)
        return signals.exit_status(exc)


if __name__ == "__main__":
    sys.exit(main())
