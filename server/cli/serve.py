"""`robocal serve` and `robocal token`: the workstation service and its API token."""

from __future__ import annotations

import sys

from .common import _whole

_port = _whole(0, 65535, "a TCP port (0 to 65535)")


def _settings(args, make_folder: bool = True):
    """The service's settings: ROBOCAL_* variables, overridden by the options given; its data
    folder made (refused in one line if it is a file)."""
    from robocal.server.calibration import workflow
    from robocal.server.service.settings import Settings

    overrides = {
        k: v
        for k, v in (
            ("database", args.db),
            ("host", args.host),
            ("port", args.port),
            ("data_dir", args.data_dir),
        )
        if v is not None
    }
    settings = Settings(**overrides)
    if settings.data_dir.exists() and not settings.data_dir.is_dir():
        raise workflow.DataError(f"{settings.data_dir}: the data folder is a file, not a folder")
    if make_folder:
        settings.data_dir.mkdir(parents=True, exist_ok=True)
    return settings


def cmd_serve(args) -> None:
    settings = _settings(args)
    from robocal.server.service.app import CannotListen, serve

    from .. import store

    store.open_database(settings.database).close()  # a wrong --db: one line, before listening
    try:
        serve(settings)
    except CannotListen as e:
        raise SystemExit(f"robocal: error: {e}") from None


def cmd_token(args) -> None:
    from robocal.server.service.security import reset_token

    settings = _settings(args, make_folder=args.action == "reset")
    path = settings.token_file
    if args.action == "reset":
        token = reset_token(path)
        print(token)
        print(
            f"robocal: a new API token (shown once, keep it); its hash is in {path}. The old "
            "token stops working at once, a running service included (it reads the file on "
            "each request): give the new one to every client and the page",
            file=sys.stderr,
        )
    elif path.exists():
        print(
            f"the token itself is kept nowhere, only its hash, in {path}; "
            f"`robocal token reset{' --data-dir ' + str(settings.data_dir) if args.data_dir else ''}`"
            " makes and prints a new one"
        )
    else:
        print(
            f"no token yet ({path} is absent): `robocal serve` makes one at its first start, "
            "or `robocal token reset` now"
        )


def add(sub) -> None:
    """The command's parser, on the command line's subparsers."""
    sv = sub.add_parser(
        "serve", help="the workstation service (REST API), on 127.0.0.1 unless told"
    )
    sv.add_argument("--db", help="database file or URL (default robocal.db, or ROBOCAL_DATABASE)")
    sv.add_argument("--host", help="address to listen on (default 127.0.0.1)")
    sv.add_argument("--port", type=_port, help="port (default 8000)")
    sv.add_argument(
        "--data-dir", help="models, recordings and the token hash (default robocal-data)"
    )
    sv.set_defaults(func=cmd_serve)

    tk = sub.add_parser(
        "token",
        help="the service's API token: reset makes a new one (the old one stops working), "
        "show says where its hash is kept",
    )
    tk.add_argument("action", choices=("reset", "show"), help="reset: a new token; show: where")
    tk.add_argument(
        "--data-dir",
        help="the service's data folder (default robocal-data, or ROBOCAL_DATA_DIR)",
    )
    tk.set_defaults(func=cmd_token, db=None, host=None, port=None)
