"""A participant written against the `coupler` package alone (scripts/native-check.sh runs it
in a fresh venv holding only the coupler wheel and its dependencies): a running sum.

    python standalone_participant.py PORT_FILE

Serves on 127.0.0.1, a free port, which it writes to PORT_FILE once it serves.
"""

from __future__ import annotations

import sys
from collections.abc import Mapping
from pathlib import Path

from coupler.channels import Causality, Channel, Description, RunSetup, Value, ValueType
from coupler.participant import Participant, Values
from coupler.server import ParticipantServer, run, serve


class Sum(Participant):
    """total = the sum of u over the steps so far, times the parameter `scale`."""

    CHANNELS = (
        Channel(name="scale", causality=Causality.PARAMETER, type=ValueType.REAL, start=1.0),
        Channel(name="u", causality=Causality.INPUT, type=ValueType.REAL, start=0.0),
        Channel(name="total", causality=Causality.OUTPUT, type=ValueType.REAL),
    )

    def __init__(self) -> None:
        self.scale = 1.0
        self.u = 0.0
        self.total = 0.0

    async def describe(self) -> Description:
        return Description(name="Sum", channels=self.CHANNELS, implementation="native-check.Sum")

    async def initialize(self, setup: RunSetup) -> Values:
        self.scale = float(setup.parameters.get("scale", 1.0))
        self.u = float(setup.inputs.get("u", 0.0))  # held until an input arrives
        self.total = 0.0
        return {"total": self.total}

    async def do_step(self, time: float, step: float, inputs: Mapping[str, Value]) -> Values:
        self.u = float(inputs.get("u", self.u))
        self.total += self.scale * self.u
        return {"total": self.total}

    async def terminate(self, reason: str = "") -> None:
        self.total = 0.0


def main(port_file: Path) -> None:
    def started(server: ParticipantServer) -> None:
        port_file.write_text(str(server.port))

    run(serve(Sum(), on_started=started))


if __name__ == "__main__":
    main(Path(sys.argv[1]))
