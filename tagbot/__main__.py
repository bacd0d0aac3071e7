"""``python -m tagbot``: the same as the ``tagbot`` command."""

from tagbot.cli import main

if __name__ == "__main__":
    raise SystemExit(main())
