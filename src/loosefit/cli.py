"""The ``loosefit`` command line: argument parsing only (:mod:`loosefit.cli_parser`); every verb
(:mod:`loosefit.cli_commands`) calls a library function. Here: errors and interrupts in one line each."""

from __future__ import annotations

import logging
import shlex
import signal
import sys
from pathlib import Path

from loosefit.cli_parser import build_parser
from loosefit.errors import LoosefitError
from loosefit.quiet import quiet_third_party

__all__ = ["build_parser", "main"]


class Stopped(KeyboardInterrupt):
    """SIGTERM, raised where Ctrl-C raises :class:`KeyboardInterrupt` (so that what is running keeps its work).

    ``Stopped.seen`` says that a SIGTERM arrived even when the exception reaches :func:`main` as a plain
    :class:`KeyboardInterrupt` (Ray's ``wait`` turns any exception of a signal handler into one)."""

    seen = False


def _on_sigterm(signum, frame):
    Stopped.seen = True
    raise Stopped()


def _kept(args, argv: list[str]) -> str:
    """What an interrupted verb kept, and the command that resumes it, in words."""
    again = shlex.join(["loosefit", *argv])
    if args.command == "simulate" and args.plan is not None:
        out = Path(args.out)
        try:
            from loosefit.data import DatasetStore

            done = len(DatasetStore.open(out, mode="r").sequence_names(status="ok"))
        except Exception:  # noqa: BLE001 - no store (nothing was stored) or one that cannot be read now
            return f"nothing was stored in {out}; run again: {again}"
        return f"{done} finished sequence(s) are kept in {out}; resume (finished ones are skipped): {again}"
    if args.command == "simulate":  # one sequence: its file is written only when the simulation is finished
        return f"nothing was written to {args.out} (a sequence is written when its simulation ends); run again: {again}"
    if args.command == "prepare":
        return (f"what was prepared is kept in {args.data} (a garment cut short is marked writing and redone); "
                f"resume: {again}")
    if args.command == "train":
        last = Path(args.out) / "checkpoints" / "last.pt"
        if args.method == "collision" or not last.is_file():
            return f"no training epoch was completed in {args.out}; run again: {again}"
        resume = again if args.resume else shlex.join(["loosefit", *argv, "--resume"])
        return f"the last completed epoch is kept in {last}; resume: {resume}"
    return f"run again: {again}"


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    args = build_parser().parse_args(argv)
    logging.basicConfig(level=logging.INFO if args.verbose else logging.WARNING, format="%(levelname)s %(name)s: %(message)s")
    Stopped.seen = False
    try:
        previous = signal.signal(signal.SIGTERM, _on_sigterm)
    except ValueError:  # not the main thread: leave SIGTERM alone
        previous = None
    try:
        with quiet_third_party(quiet=not args.verbose):  # Warp's start-up banner and load timings: with -v only
            args.func(args)
    except LoosefitError as e:
        print(f"loosefit {args.command}: error: {e}", file=sys.stderr)
        return 2
    except KeyboardInterrupt as e:  # Ctrl-C or SIGTERM: one line, no traceback
        term = isinstance(e, Stopped) or Stopped.seen
        print(f"loosefit {args.command}: interrupted ({'SIGTERM' if term else 'SIGINT'}): {_kept(args, argv)}",
              file=sys.stderr)
        return 143 if term else 130
    finally:
        if previous is not None:
            signal.signal(signal.SIGTERM, previous)
    return 0


if __name__ == "__main__":
    sys.exit(main())
