"""A gain/integrator participant with a channel of every type. Template for new participants.

Per step from t to t + h, with inputs held over the step (explicit Euler for the integral):

    y        = gain * u                 Real [m/s]
    x        = x + u * h                Real [m]       (x starts at parameter x0)
    count    = n + offset               Integer
    inverted = not flag                 Boolean
    echo     = label                    String
    blob_out = blob, its bytes in reverse order                  Binary
"""

from __future__ import annotations

from collections.abc import Mapping

from coupler.channels import Causality, Channel, Description, RunSetup, Value, ValueType
from coupler.participant import Participant, Values

_I, _O, _P = Causality.INPUT, Causality.OUTPUT, Causality.PARAMETER
_R, _N, _B, _S, _X = (
    ValueType.REAL,
    ValueType.INTEGER,
    ValueType.BOOLEAN,
    ValueType.STRING,
    ValueType.BINARY,
)

CHANNELS = (
    Channel(
        name="gain", causality=_P, type=_R, start=2.0, description="factor of y and train speed"
    ),
    Channel(name="x0", causality=_P, type=_R, unit="m", start=0.0, description="initial integral"),
    Channel(name="offset", causality=_P, type=_N, start=0, description="added to n"),
    Channel(name="u", causality=_I, type=_R, unit="m/s", start=0.0),
    Channel(name="n", causality=_I, type=_N, start=0),
    Channel(name="flag", causality=_I, type=_B, start=False),
    Channel(name="label", causality=_I, type=_S, start=""),
    Channel(name="blob", causality=_I, type=_X, start=b"", description="any bytes"),
    Channel(name="y", causality=_O, type=_R, unit="m/s", description="gain * u"),
    Channel(name="x", causality=_O, type=_R, unit="m", description="integral of u"),
    Channel(name="count", causality=_O, type=_N, description="n + offset"),
    Channel(name="inverted", causality=_O, type=_B, description="not flag"),
    Channel(name="echo", causality=_O, type=_S, description="label"),
    Channel(name="blob_out", causality=_O, type=_X, description="blob reversed"),
)


class GainParticipant(Participant):
    """See the module docstring for the equations."""

    def __init__(self, name: str = "Gain") -> None:
        self.name = name
        self._parameters: dict[str, Value] = {}
        self._inputs: dict[str, Value] = {}
        self._x = 0.0

    async def describe(self) -> Description:
        return Description(
            name=self.name, channels=CHANNELS, implementation="coupler.examples.gain"
        )

    async def initialize(self, setup: RunSetup) -> Values:
        defaults = {c.name: c.start for c in CHANNELS if c.start is not None}
        self._parameters = {
            c.name: setup.parameters.get(c.name, defaults[c.name])
            for c in CHANNELS
            if c.causality is _P
        }
        self._inputs = {
            c.name: setup.inputs.get(c.name, defaults[c.name])
            for c in CHANNELS
            if c.causality is _I
        }
        self._x = float(self._parameters["x0"])
        return self._outputs()

    async def do_step(self, time: float, step: float, inputs: Mapping[str, Value]) -> Values:
        self._inputs.update(inputs)
        self._x += float(self._inputs["u"]) * step
        return self._outputs()

    async def terminate(self, reason: str = "") -> None:
        self._inputs = {}

    def _outputs(self) -> Values:
        gain = float(self._parameters["gain"])
        return {
            "y": gain * float(self._inputs["u"]),
            "x": self._x,
            "count": int(self._inputs["n"]) + int(self._parameters["offset"]),
            "inverted": not self._inputs["flag"],
            "echo": str(self._inputs["label"]),
            "blob_out": bytes(self._inputs["blob"])[::-1],
        }
