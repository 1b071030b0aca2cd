"""``coupler`` / ``python -m coupler_orchestrator``."""

from __future__ import annotations

import sys

from coupler_orchestrator.cli import main as cli_main


def main() -> None:
    sys.exit(cli_main(supervise=True))


if __name__ == "__main__":
    main()
