"""A mosaik API v3 simulator to try the participant with: ``Gain``, the mosaik twin of Coupler's
example gain participant (``coupler.examples.gain``).

Per step at tick k, with the input u given at k and dt = time_resolution * step_size::

    y = gain * u            (Real)
    x = x + u * dt          (Real; x starts at x0)

    python -m coupler_mosaik.examples HOST:PORT     (mosaik's "cmd" starter: %(addr)s)
"""

from __future__ import annotations

from typing import Any

import mosaik_api_v3
from mosaik_api_v3.types import CreateResult, Meta

META: Meta = {
    "api_version": "3.0",
    "type": "time-based",
    "models": {"Gain": {"public": True, "params": ["gain", "x0"], "attrs": ["u", "y", "x"]}},
}


class Gain(mosaik_api_v3.Simulator):
    """Entities y = gain * u and x = integral of u (explicit Euler), stepped every step_size."""

    def __init__(self) -> None:
        super().__init__(META)
        self.entities: dict[str, dict[str, float]] = {}
        self.step_size = 1
        self.dt = 1.0

    def init(
        self, sid: str, time_resolution: float = 1.0, step_size: int = 1, **params: Any
    ) -> Meta:
        self.step_size = step_size
        self.dt = time_resolution * step_size
        return self.meta

    def create(
        self, num: int, model: str, gain: float = 2.0, x0: float = 0.0, **unknown: Any
    ) -> list[CreateResult]:
        if unknown:
            raise ValueError(f"Gain takes gain and x0, not {sorted(unknown)}")
        created: list[CreateResult] = []
        for i in range(len(self.entities), len(self.entities) + num):
            eid = f"{model}-{i}"
            self.entities[eid] = {"gain": gain, "u": 0.0, "y": 0.0, "x": x0}
            created.append({"eid": eid, "type": model})
        return created

    def step(self, time: int, inputs: dict[str, Any], max_advance: int) -> int:
        for eid, state in self.entities.items():
            for attr, sources in inputs.get(eid, {}).items():
                state[attr] = float(sum(sources.values()))
            if time > 0:  # the first step only reads its inputs: x is x0 at the start
                state["x"] += state["u"] * self.dt
            state["y"] = state["gain"] * state["u"]
        return time + self.step_size

    def get_data(self, outputs: dict[str, list[str]]) -> dict[str, dict[str, float]]:
        return {eid: {a: self.entities[eid][a] for a in attrs} for eid, attrs in outputs.items()}


if __name__ == "__main__":
    mosaik_api_v3.start_simulation(Gain(), "A mosaik gain simulator (coupler_mosaik.examples).")
