"""The CPython extension of csrc/rows.c: results.csv's lines, and the rows of the native FMU
step read from its arrays (compiled; see coupler_native)."""

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

class RowRead:
    """Rows of Values read from memory: per column, its slot's address and its C type ('d'
    double, 'i' int, 'q' int64, 'b' int as a Boolean, '?' bool, 's' char * as a str)."""

    def __init__(self, addresses: Sequence[int], codes: str) -> None: ...
    def row(self) -> list[Any]:
        """The columns' values as they are now."""
