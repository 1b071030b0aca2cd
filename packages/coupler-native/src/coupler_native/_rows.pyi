"""The CPython extension of csrc/rows.c: results.csv's lines (compiled; see coupler_native)."""

from collections.abc import Callable, Sequence
from typing import Any

class RowFormat:
    """The lines of a run's rows: per cell after the time, its index in a row, its kind
    ('r' Real, 'i' Integer, 'b' Boolean, 's' String, 'o' other) and, for kinds 's' and
    'o', its formatter."""

    def __init__(
        self,
        indices: Sequence[int],
        kinds: str,
        formatters: tuple[Callable[[Any], str] | None, ...],
    ) -> None: ...
    def line(self, time: float, row: Sequence[Any]) -> str:
        """The CSV line of the picked cells of ``row``, with its newline."""
