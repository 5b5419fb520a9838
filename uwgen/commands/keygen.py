"""`uwgen keygen PATH`: write a new network master key for the secure link.

    uwgen keygen keys/demo.key            # refuses to replace an existing key
    uwgen keygen keys/demo.key --force    # replaces it (every side needs the new copy)

The file is readable by its owner only (0600). Give every side of the network a copy and
name it in the manifest (`security: {key_file: ...}`); the key itself is never in the
manifest. Exit status 0 on success, 2 when the file exists (without --force) or cannot
be written.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

HELP = "write a new network master key file (owner-only) for the secure link"
EXIT_USAGE = 2


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("path", type=Path, metavar="PATH", help="key file to write")
    parser.add_argument("--force", action="store_true",
                        help="replace an existing key file (every side must then get the new key)")


def run(args: argparse.Namespace) -> int:
    from uwgen.security.keys import SecurityError, write_key_file
    try:
        write_key_file(args.path, force=args.force)
    except SecurityError as exc:
        print(f"uwgen keygen: {exc}", file=sys.stderr)
        return EXIT_USAGE
    except OSError as exc:
        print(f"uwgen keygen: cannot write {args.path}: {exc.strerror or exc}", file=sys.stderr)
        return EXIT_USAGE
    print(f"wrote a new network key to {args.path} (mode 0600); copy it to every side of the "
          "network and name it in the manifest: security: {key_file: ...}")
    return 0
