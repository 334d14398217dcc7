"""The ``robofabric`` console script: warn about a replaced ``fabric`` package, then run :func:`fabric.cli.main`."""

from __future__ import annotations

import sys

from robofabric.clash import fabric_clash


def main(argv: list[str] | None = None) -> int:
    warning = fabric_clash()
    if warning:
        print(warning, file=sys.stderr)
    try:
        from fabric.cli import main as fabric_main
    except ImportError as exc:
        print(f"error: robofabric's package 'fabric' cannot be imported ({exc})", file=sys.stderr)
        if not warning:
            print("hint: is another package named 'fabric' on the path? (`pip show fabric`)", file=sys.stderr)
        return 2
    return fabric_main(argv)


if __name__ == "__main__":
    sys.exit(main())
