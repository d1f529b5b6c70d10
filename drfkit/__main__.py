"""``python -m drfkit <command> [args]``: the command lines live in ``drfkit.cli``."""
from drfkit.cli import main

if __name__ == "__main__":
    raise SystemExit(main())
