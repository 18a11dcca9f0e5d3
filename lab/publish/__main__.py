"""``python -m sray.lab.publish [--check] [--repo DIR]``: rewrite every generated block of README.md and docs/ and
every benchmark page from the stored results; ``--check`` only lists the files that are out of date (exit 1)."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from sray.lab.publish.publish import publish


def main(argv: list[str] | None = None) -> int:
    """Run the publisher; 0 when every file is (now) up to date, 1 when ``--check`` finds one that is not, 2 on a
    bad block or result file."""
    parser = argparse.ArgumentParser(prog="python -m sray.lab.publish", description=__doc__)
    parser.add_argument("--check", action="store_true", help="list the files that are out of date; write nothing")
    parser.add_argument("--repo", type=Path, default=Path("."), help="repository folder (default: here)")
    args = parser.parse_args(argv)
    try:
        stale = publish(args.repo, check=args.check)
    except (ValueError, OSError) as error:
        print(f"sray.lab.publish: {error}", file=sys.stderr)
        return 2
    for path in stale:
        print(f"{'out of date' if args.check else 'written'}: {path}")
    if not stale:
        print("every published number is up to date")
    return 1 if args.check and stale else 0


if __name__ == "__main__":
    sys.exit(main())
