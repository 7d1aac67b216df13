"""``python -m service keys add|list|revoke``: the API keys file (:mod:`service.api_keys`).

    python -m service keys add NAME --scopes use,manage   # prints the new key, once
    python -m service keys list
    python -m service keys revoke NAME

The file is ``--file`` or ``$MOTION_API_KEYS_FILE``. ``add`` writes only the key to stdout
(``KEY=$(python -m service keys add ci --scopes use)``) and what it did to stderr; the key
cannot be shown again: lose it, revoke it and add another. A running service reads the file
again when it changes, so a revoked key is refused at once, with no restart.
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

from service.api_keys import SCOPES, KeysFileError, add_key, parse_scopes, read_keys, revoke_key

ENV = "MOTION_API_KEYS_FILE"


def parser() -> argparse.ArgumentParser:
    top = argparse.ArgumentParser(
        prog="python -m service keys", description="Add, list and revoke API keys."
    )
    top.add_argument("--file", type=Path, help=f"the keys file (default: ${ENV})")
    commands = top.add_subparsers(dest="command", required=True)
    add = commands.add_parser("add", help="make a key; prints it once")
    add.add_argument("name", help="the key's name (in logs and metrics): a-z, 0-9, _ and -")
    add.add_argument(
        "--scopes", default="use", help=f"comma-separated: {', '.join(SCOPES)} (default: use)"
    )
    commands.add_parser("list", help="names, scopes and dates (never the keys)")
    revoke = commands.add_parser("revoke", help="remove a key; services refuse it at once")
    revoke.add_argument("name")
    return top


def main(argv: list[str] | None = None) -> int:
    args = parser().parse_args(argv)
    path = args.file or (Path(os.environ[ENV]) if os.environ.get(ENV) else None)
    if path is None:
        print(f"keys: name the keys file with --file or {ENV}", file=sys.stderr)
        return 2
    try:
        if args.command == "add":
            try:
                scopes = parse_scopes(args.scopes)
            except ValueError as exc:
                print(f"keys: {exc}", file=sys.stderr)
                return 2
            key = add_key(path, args.name, scopes)
            print(key)
            print(
                f"added {args.name!r} ({','.join(s for s in SCOPES if s in scopes)}) to {path}; "
                "the key above is not stored and will not be shown again",
                file=sys.stderr,
            )
        elif args.command == "list":
            for key in read_keys(path):
                scopes = ",".join(s for s in SCOPES if s in key.scopes)
                print(f"{key.name}\t{scopes}\t{key.created or '-'}")
        elif not revoke_key(path, args.name):
            print(f"keys: no key named {args.name!r} in {path}", file=sys.stderr)
            return 1
        else:
            print(f"revoked {args.name!r} in {path}", file=sys.stderr)
    except KeysFileError as exc:
        print(f"keys: {exc}", file=sys.stderr)
        return 1
    return 0
