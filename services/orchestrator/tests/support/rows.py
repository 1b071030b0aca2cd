"""Any row results.csv may be asked to write, drawn by hypothesis (test_correctness.py,
outputs/test_csv_rows.py)."""

from __future__ import annotations

from hypothesis import strategies as st

CELLS = {
    "Real": st.floats(allow_nan=True) | st.integers(),
    "Integer": st.integers(),
    "Enumeration": st.integers(),
    "UInt64": st.integers(min_value=0, max_value=2**64 - 1),
    "Boolean": st.booleans() | st.integers(),
    "String": st.text(),
    "Binary": st.binary(),
}


RESULT_ROWS = st.lists(st.sampled_from(sorted(CELLS)), min_size=1, max_size=8).flatmap(
    lambda types: st.tuples(
        st.just(types),
        st.tuples(*(CELLS[t] for t in types)),
        st.sets(st.integers(0, len(types) - 1)),
        st.floats(allow_nan=False),
    )
)
"""(column types, a row of values of them, the picked columns, the time): any row results.csv
may be asked to write."""
