"""What one command has seen, for its last words: the participants it waited for, the run's
progress and end, where the results go."""

from __future__ import annotations

import argparse
import re
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from coupler_orchestrator.cli.exits import EXIT_INTERRUPTED, EXIT_OK
from coupler_orchestrator.observer import Observer, RunEnd, RunInfo, Steps

if TYPE_CHECKING:
    from coupler_orchestrator.outputs.monitor import MonitorServer


class Session(Observer):
    """What one command has seen, for its last words: the participants it waited for (printed
    at once, one line each), the run's progress and end, where the results go."""

    def __init__(self) -> None:
        self.waited_for: list[str] = []
        self.info: RunInfo | None = None
        self.time: float | None = None
        self.end: RunEnd | None = None
        self.out_dir: Path | None = None
        self.campaign: Path | None = None
        self.monitor: MonitorServer | None = None

    def waiting(self, name: str, address: str, reason: str) -> None:
        self.waited_for.append(name)
        if self.monitor is not None:
            self.monitor.state.waiting(name, address, reason)
        print(f"waiting for {name} at {address} ({reason})", file=sys.stderr, flush=True)

    def results_in(self, folder: Path) -> None:
        """The run's results folder, once it is chosen."""
        self.out_dir = folder

    def started(self, info: RunInfo) -> None:
        self.info, self.end = info, None

    def stepped(self, time: float, row: Sequence[Any]) -> None:
        self.time = time

    def stepped_batch(self, steps: Steps) -> None:
        self.time = steps.times[-1]

    def finished(self, end: RunEnd) -> None:
        self.end = end

    def interrupted(self, args: argparse.Namespace) -> tuple[int, str]:
        """The exit code and the one sentence Ctrl-C (or SIGTERM) ends a command with."""
        if self.campaign is not None:
            return EXIT_INTERRUPTED, (
                f"interrupted the campaign; the runs that ended are in "
                f"{shown(self.campaign / 'campaign.csv')} (the same command again runs the rest)"
            )
        if args.command == "replay":
            return EXIT_OK, "stopped serving the recording"
        where = shown(self.out_dir) if self.out_dir else "no folder yet"
        end = self.end
        if end is not None and end.status != "aborted":
            return EXIT_OK, (
                f"stopped the services; the run had ended {end.status} at t={end.end_time:g} s, "
                f"results in {where}"
            )
        if self.info is None:
            return EXIT_INTERRUPTED, "interrupted before the run started; nothing was recorded"
        reached = end.end_time if end is not None else self.time
        at = f"t={reached:g} s" if reached is not None else "the start"
        return EXIT_INTERRUPTED, (
            f"interrupted at {at} of {self.info.stop_time:g} s; the results so far are in "
            f"{where} (summary.json: status aborted)"
        )


def shown(path: Path) -> str:
    """``path`` relative to the working directory when it is below it."""
    try:
        return str(path.resolve().relative_to(Path.cwd()))
    except ValueError:
        return str(path)


def start_hint(args: argparse.Namespace) -> str:
    """How to start the scenario's services: its fleet file (and the make target running it)
    when there is one beside the SSD."""
    ssp = getattr(args, "ssp", None)
    fleet = ssp.resolve().parent / "fleet.toml" if ssp is not None else None
    if fleet is None or not fleet.exists():
        return "start the participants first (see the scenario's README), then run again"
    file = shown(fleet)
    command = f"`.venv/bin/coupler fleet {file}`"
    makefile = Path("Makefile")
    if makefile.exists():
        target = re.search(
            rf"^([\w-]+):[^\n]*\n(?:\t[^\n]*\n)*?\t[^\n]*coupler fleet {re.escape(file)}\b",
            makefile.read_text(encoding="utf-8", errors="replace"),
            re.MULTILINE,
        )
        if target:
            command += f" or `make {target.group(1)}`"
    return (
        f"start the scenario's services with {command} (it starts them and runs the scenario), "
        f"or start each one yourself"
    )
