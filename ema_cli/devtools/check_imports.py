"""Import every module of ``ema_cli``: run by ``make run`` in the runtime environment (before any
test extra is installed), so a third-party import the runtime does not declare fails at once,
naming the module and the missing package. ``deptry`` in ``make test`` checks the same
statically.

Usage: ``python -m ema_cli.devtools.check_imports``
"""

from __future__ import annotations

import importlib
import pkgutil
import sys

import ema_cli


def modules() -> list[str]:
    """The dotted names of every module and package of ``ema_cli``, sorted."""
    names = {m.name for m in pkgutil.walk_packages(ema_cli.__path__, "ema_cli.")}
    return sorted(names | {"ema_cli"})


def main() -> int:
    """Import them all -> exit code (1 and one line per failure)."""
    failed = 0
    names = modules()
    for name in names:
        try:
            importlib.import_module(name)
        except ImportError as exc:
            failed += 1
            missing = getattr(exc, "name", None) or "?"
            print(f"error: {name} cannot be imported: {exc} (missing package: {missing}; "
                  f"declare it in pyproject.toml and run `make lock`)", file=sys.stderr)
    if failed:
        return 1
    print(f"imports: all {len(names)} modules of ema_cli import with the runtime dependencies")
    return 0


if __name__ == "__main__":
    sys.exit(main())
