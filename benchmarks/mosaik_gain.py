"""The example gain participant as a mosaik 3 simulator (mosaik-api-v3), for `make bench`: mosaik
starts it as its own process and steps it over its TCP API, as Coupler steps a gain participant
over gRPC. Also the local source and sink of that benchmark's world.

    python benchmarks/mosaik_gain.py HOST:PORT      (mosaik's 'cmd' starts it so)
"""

from __future__ import annotations

from typing import Any

import mosaik_api_v3

META = {
    "type": "time-based",
    "models": {
        "Gain": {"public": True, "params": [], "attrs": ["u", "y", "x"]},
        "Source": {"public": True, "params": [], "attrs": ["value"]},
        "Sink": {"public": True, "params": [], "attrs": ["y"]},
    },
}


class Simulator(mosaik_api_v3.Simulator):  # type: ignore[misc]
    """Gain: y = 4 u, x integrates u; Source: a ramp; Sink: keeps what it gets."""

    def __init__(self) -> None:
        super().__init__(META)
        self.entities: dict[str, dict[str, float]] = {}
        self.model = ""

    def init(self, sid: str, time_resolution: float = 1.0, **params: Any) -> dict[str, Any]:
        return self.meta  # type: ignore[no-any-return]

    def create(self, num: int, model: str, **params: Any) -> list[dict[str, str]]:
        self.model = model
        created = []
        for i in range(len(self.entities), len(self.entities) + num):
            eid = f"{model}-{i}"
            self.entities[eid] = {"u": 0.0, "y": 0.0, "x": 0.0, "value": 0.0}
            created.append({"eid": eid, "type": model})
        return created

    def step(self, time: int, inputs: dict[str, Any], max_advance: int) -> int:
        for eid, state in self.entities.items():
            for attr, sources in inputs.get(eid, {}).items():
                state[attr] = float(sum(sources.values()))
            if self.model == "Gain":
                state["y"] = 4.0 * state["u"]
                state["x"] += state["u"] * 0.01
            elif self.model == "Source":
                state["value"] = time * 0.01
        return time + 1

    def get_data(self, outputs: dict[str, list[str]]) -> dict[str, dict[str, float]]:
        return {eid: {a: self.entities[eid][a] for a in attrs} for eid, attrs in outputs.items()}


if __name__ == "__main__":
    mosaik_api_v3.start_simulation(Simulator())
