"""The CPython extension of csrc/fmu_steps.c (csrc/fmu_steps_module.c): the native FMU step
(compiled; see coupler_native)."""

from collections.abc import Sequence

CK_DONE: int
CK_NO_MEMORY: int
CK_CLAIMED: int
CK_CALL_SET: int
CK_CALL_STEP: int
CK_CALL_GET: int
CK_CALL_TERMINATE: int

Call = tuple[int, int, int, int]
"""A ``ck_call``: (function, value references, count, buffer), addresses and a count."""
Copy = tuple[int, int, int]
"""A ``ck_copy``: (target, source, size)."""

class Log:
    """``ck_log_new(cells, slots, capacity)``, freed with this object; ``cells``: each column's
    (slot address, C type code: 'd', 'i', 'q', 'b', '?' or 's'). MemoryError when there is
    no memory for it."""

    def __init__(self, cells: Sequence[tuple[int, str]], slots: int, capacity: int) -> None: ...
    @property
    def address(self) -> int:
        """The ``ck_log *`` (what ``coupler_native._rows.RowLog`` reads)."""
    def take(self) -> int:
        """``ck_log_take``: the rows of the last ``Members.steps``, handed over once."""
    def claim(self) -> int:
        """``ck_log_claim``: from another thread, the rows of a ``steps`` under way."""

class Members:
    """The members of a run as ``ck_step`` steps them, built once: each (instance, do_step,
    step, version, slot, copies, sets, gets); ``timing``, ``watch``, ``stop``: the addresses of
    the arrays the steps write (double[members], double[3], int[3])."""

    def __init__(
        self,
        members: Sequence[
            tuple[int, int, float, int, int, Sequence[Copy], Sequence[Call], Sequence[Call]]
        ],
        timing: int,
        watch: int,
        stop: int,
        jacobi: bool,
    ) -> None: ...
    def step(self, start: int, time: float, /) -> int:
        """``ck_step`` from member ``start`` at ``time`` (without the GIL)."""
    def steps(
        self,
        origin: float,
        stride: float,
        scale: float,
        k0: int,
        count: int,
        budget: float,
        log: Log,
        /,
    ) -> int:
        """``ck_steps`` (without the GIL), each step logged in ``log``."""
    def last(self, index: int, /) -> float:
        """The member's last successful time (``fmi3DoStep``'s answer)."""
