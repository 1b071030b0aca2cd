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
    def lines(self, log: RowLog, first: int, every: int) -> str | None:
        """The lines of the log's rows ``first``, ``first + every``, ...; None when a cell's
        kind cannot be made from its column's C type in the log."""

class RowRead:
    """Rows of Values read from memory: per column, its slot's address and its C type ('d'
    double, 'i' int, 'q' int64, 'b' int as a Boolean, '?' bool, 's' char * as a str)."""

    def __init__(self, addresses: Sequence[int], codes: str) -> None: ...
    def row(self) -> list[Any]:
        """The columns' values as they are now."""

class RowLog:
    """The rows of a native FMU step's ``ck_log`` (at ``address``; ``owner`` keeps it)."""

    def __init__(self, address: int, owner: Any) -> None: ...
    def __len__(self) -> int: ...
    def times(self) -> list[float]:
        """Each logged row's time."""
    def row(self, j: int) -> list[Any]:
        """Row ``j``'s values, as ``RowRead`` read them then."""
    def seconds(self, j: int) -> list[float]:
        """Each member's wall time of step ``j`` [s]."""
    def samples(self, member: int) -> list[float]:
        """The member's wall time of each logged step [s]."""

def log_buckets(
    samples: list[float], floor: float, per_bucket: float, base: float
) -> tuple[float, float, dict[int, int]]:
    """(total, maximum, {bucket: count}) of ``samples``: each one's bucket
    ``int((log(s) - floor) * per_bucket) if s > base else 0``."""
