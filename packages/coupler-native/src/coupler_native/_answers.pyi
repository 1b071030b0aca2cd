"""The CPython extension of csrc/answers.c: a step's answer read in C (compiled; see
coupler_native)."""

from typing import Any

class AnswerRead:
    """A participant's step answers: ``fields`` maps each output channel to (its
    VariableBinding field number, the weight of a value's length in a message's size, whether
    a Real must be finite); ``max_bytes`` bounds the weighted sum."""

    def __init__(self, fields: dict[str, tuple[int, int, bool]], max_bytes: int) -> None: ...
    def read(self, data: Any) -> tuple[dict[str, Any], float, float] | None:
        """A serialized DoStepResponse in its plain form: its outputs (as
        ``coupler.wire.Codec.decode`` makes them), its ``step_seconds`` and ``waited_seconds``
        (0.0 where it does not say); None for any other."""
