"""`python scripts/fleet.py FLEET.toml` is `coupler fleet FLEET.toml` (kept for habit)."""

import sys

from coupler_orchestrator.cli.main import main

if __name__ == "__main__":
    sys.exit(main(["fleet", *sys.argv[1:]]))
