"""The `robocal` command line: one module per command, each with its parser (`add`)."""

from __future__ import annotations

import argparse
import sys

from . import (
    acquire,
    bench,
    calibrate,
    check,
    compare,
    compensate,
    demo,
    diagnose,
    evaluate,
    export,
    fleet,
    predict,
    schema,
    serve,
    simulate,
)


class Parser(argparse.ArgumentParser):
    """argparse, but a mistake is one line (not the usage block), with a "did you mean"."""

    def error(self, message: str):
        import difflib
        import re

        m = re.search(r"invalid choice: '([^']*)' \(choose from (.*)\)", message)
        if m:
            choices = [c.strip(" '") for c in m.group(2).split(",")]
            close = difflib.get_close_matches(m.group(1), choices, n=1)
            if close:
                message += f"; did you mean {close[0]!r}?"
        elif message.startswith("unrecognized arguments:"):
            known = self._option_strings()
            command = self._command()
            for word in message.split(":", 1)[1].split():
                option = word.split("=")[0]
                close = difflib.get_close_matches(option, known, n=1)
                if not word.startswith("--"):
                    continue
                if option in known:  # another command's option: say so, not "did you mean" itself
                    message += f"; {option} is not an option of {command or 'this command'}"
                elif close:
                    message += f"; {word}: did you mean {close[0]}?"
        self.exit(2, f"{self.prog}: error: {message} (see {self.prog} --help)\n")

    def parse_known_args(self, args=None, namespace=None):
        self._argv = list(sys.argv[1:] if args is None else args)
        return super().parse_known_args(args, namespace)

    def _command(self) -> str | None:
        """The command the arguments named ("robocal evaluate"), None before one was parsed."""
        for action in self._actions:
            if isinstance(action, argparse._SubParsersAction):
                for word in getattr(self, "_argv", []):
                    if word in action.choices:
                        return f"{self.prog} {word}"
        return None

    def _option_strings(self) -> list[str]:
        """Every long option of this parser and of its commands."""
        out = []
        for action in self._actions:
            out += [o for o in action.option_strings if o.startswith("--")]
            if isinstance(action, argparse._SubParsersAction):
                for sub in action.choices.values():
                    out += sub._option_strings()
        return sorted(set(out))


def build_parser() -> argparse.ArgumentParser:
    p = Parser(prog="robocal", description="Robot calibration with a laser tracker.")
    sub = p.add_subparsers(dest="command", required=True, metavar="COMMAND", help="what to do")

    simulate.add(sub)
    calibrate.add(sub)
    predict.add(sub)
    compensate.add(sub)
    evaluate.add(sub)
    check.add(sub)
    fleet.add(sub)
    compare.add(sub)
    diagnose.add(sub)
    acquire.add(sub)
    serve.add(sub)
    demo.add(sub)
    export.add(sub)
    schema.add(sub)
    bench.add(sub)
    return p


def main(argv=None) -> int:
    args = build_parser().parse_args(argv)
    if args.command == "demo" and args.effect is None:
        args.effect = ["joint_compliance:2"]
    try:
        from .common import refuse_overwriting

        refuse_overwriting(args)
        code = args.func(args)
    except KeyboardInterrupt:  # before or after any motion
        print("robocal: interrupted", file=sys.stderr)
        return 130
    except Exception as e:  # noqa: BLE001 - the expected kinds get one line; others propagate
        # imported here, not at the top: `robocal --help` must not wait for scipy and the store
        from robocal.server.acquisition.acquire import AcquisitionFailed, Interrupted
        from robocal.server.calibration.workflow import DataError
        from robocal.solver.identifiability import NotIdentifiable

        from ..formats.errors import InputError
        from ..store import StoreError

        if isinstance(e, Interrupted):  # Ctrl-C of a run: the arm was e-stopped first
            print(f"robocal: {e}", file=sys.stderr)
            return 130
        if isinstance(e, NotIdentifiable) and getattr(args, "meas", None):
            print(f"robocal: error: {args.meas}: {e}", file=sys.stderr)  # the data it fits
            return 1
        if isinstance(e, (InputError, DataError, NotIdentifiable, AcquisitionFailed, StoreError)):
            print(f"robocal: error: {e}", file=sys.stderr)
            return 1
        if isinstance(e, FileNotFoundError):
            print(f"robocal: error: {e.filename}: no such file", file=sys.stderr)
            return 1
        if isinstance(e, OSError) and e.filename is not None:  # a folder, no permission...
            print(f"robocal: error: {e.filename}: {e.strerror or e}", file=sys.stderr)
            return 1
        if _is_settings_error(e):
            print(f"robocal: error: {_settings_error_line(e)}", file=sys.stderr)
            return 1
        if isinstance(e, ValueError):
            print(f"robocal: error: {e}", file=sys.stderr)
            return 1
        raise
    return code if isinstance(code, int) else 0


def _is_settings_error(e: Exception) -> bool:
    # pydantic is imported only if the settings were built: `robocal --help` stays light.
    pydantic = sys.modules.get("pydantic")
    return pydantic is not None and isinstance(e, pydantic.ValidationError)


def _settings_error_line(e) -> str:
    """A settings ValidationError (from ROBOCAL_* variables) as one line naming the setting."""
    first = e.errors()[0]
    name = ".".join(str(x) for x in first["loc"])
    more = f" (and {e.error_count() - 1} more)" if e.error_count() > 1 else ""
    return (
        f"setting {name!r} (ROBOCAL_{name.upper()}): {first['msg']}, "
        f"not {first.get('input')!r}{more}"
    )


__all__ = ["build_parser", "main"]
