"""A campaign's types: its variants (grid, listed, sampled; made as they are asked for), the
campaign file read (``CampaignSpec`` and its parts), one run as a worker is given it
(``RunJob``) and as it comes back (``RunReport``), and the whole campaign's result. The
modules that read (``spec``, ``variants``), run (``worker``, ``execution``) and show
(``table``, ``progress``) a campaign all speak these."""

from __future__ import annotations

import itertools
import math
import random
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import overload

from coupler.errors import ScenarioError

Scalar = float | int | str | bool
"""A variant's value, an output's value."""

COMPLETED = ("completed", "terminated")
"""Run statuses a re-run skips."""

REDUCTIONS = ("max", "min", "first", "last", "mean", "count_changes")
"""How an output reduces its results.csv column to one value."""


@dataclass(frozen=True)
class Grid:
    """Every combination of the axes' values, the last axis varying fastest (as
    ``itertools.product``)."""

    axes: tuple[tuple[str, tuple[Scalar, ...]], ...]

    def __len__(self) -> int:
        return math.prod(len(values) for _, values in self.axes) if self.axes else 0

    def __getitem__(self, index: int) -> dict[str, Scalar]:
        variant: dict[str, Scalar] = {}
        for key, values in reversed(self.axes):
            index, digit = divmod(index, len(values))
            variant[key] = values[digit]
        return {key: variant[key] for key, _ in self.axes}

    def names(self) -> list[str]:
        return [key for key, _ in self.axes]


@dataclass(frozen=True)
class Listed:
    """Variants written out: [[variant]] tables, [table] rows."""

    variants: tuple[dict[str, Scalar], ...]

    def __len__(self) -> int:
        return len(self.variants)

    def __getitem__(self, index: int) -> dict[str, Scalar]:
        return dict(self.variants[index])

    def names(self) -> list[str]:
        return list(dict.fromkeys(k for v in self.variants for k in v))


@dataclass(frozen=True)
class Sample:
    """``count`` variants drawn by the laws; the i-th from a generator seeded by the seed and
    i, so any one is made alone and always the same."""

    count: int
    seed: int
    laws: tuple[tuple[str, str, tuple[Scalar, ...]], ...]
    """(key, "uniform" or "choice", bounds or choices)."""

    def __len__(self) -> int:
        return self.count

    def __getitem__(self, index: int) -> dict[str, Scalar]:
        draw = random.Random(f"{self.seed}/{index}")
        variant: dict[str, Scalar] = {}
        for key, law, values in self.laws:
            if law == "uniform":
                low, high = values
                variant[key] = draw.uniform(float(low), float(high))
            else:
                variant[key] = draw.choice(values)
        return variant

    def names(self) -> list[str]:
        return [key for key, _, _ in self.laws]


Part = Grid | Listed | Sample


class Variants(Sequence[dict[str, Scalar]]):
    """A campaign's variants, all sections in order (grid, [[variant]], table, sample), each
    made when it is asked for; a slice is a tuple."""

    def __init__(self, parts: Sequence[Part]) -> None:
        self.parts = tuple(p for p in parts if len(p))
        self._ends = list(itertools.accumulate(len(p) for p in self.parts))

    def __len__(self) -> int:
        return self._ends[-1] if self._ends else 0

    @overload
    def __getitem__(self, index: int) -> dict[str, Scalar]: ...
    @overload
    def __getitem__(self, index: slice) -> tuple[dict[str, Scalar], ...]: ...
    def __getitem__(self, index: int | slice) -> dict[str, Scalar] | tuple[dict[str, Scalar], ...]:
        if isinstance(index, slice):
            return tuple(self[i] for i in range(*index.indices(len(self))))
        if index < 0:
            index += len(self)
        if not 0 <= index < len(self):
            raise IndexError(index)
        for part, end in zip(self.parts, self._ends, strict=True):
            if index < end:
                return part[index - end + len(part)]
        raise AssertionError  # unreachable: the index is below the last end

    def __iter__(self) -> Iterator[dict[str, Scalar]]:
        for part in self.parts:
            for i in range(len(part)):
                yield part[i]

    def __eq__(self, other: object) -> bool:
        return isinstance(other, Variants) and self.parts == other.parts

    def __hash__(self) -> int:
        return hash(len(self))

    def __repr__(self) -> str:
        return f"Variants({', '.join(f'{type(p).__name__.lower()} {len(p)}' for p in self.parts)})"

    def names(self) -> list[str]:
        """Every key a variant may have, in order of appearance (the table's columns)."""
        return list(dict.fromkeys(k for p in self.parts for k in p.names()))


class CampaignError(ScenarioError):
    """A campaign file that cannot be run as written."""


@dataclass(frozen=True, kw_only=True)
class Output:
    """A campaign table column read off a run's results.csv, or its summary.json's reports."""

    name: str
    reduction: str
    """One of REDUCTIONS."""
    channel: str
    """``Component.connector`` (a results.csv column), or ``reports.<report>.<key>...`` (a
    value of summary.json's reports: ``reports.perception.recall``)."""


@dataclass(frozen=True, kw_only=True)
class Derive:
    """Columns computed by ``function(finished, **options)`` from a finished run."""

    function: str
    """``package.module:function``."""
    options: dict[str, Scalar] = field(default_factory=dict)


@dataclass(frozen=True, kw_only=True)
class Check:
    """A true/false column: an expression over outputs, derived values and parameters."""

    name: str
    expression: str


@dataclass(frozen=True, kw_only=True)
class ScenarioSpec:
    """What every run of the campaign runs."""

    root: Path
    """Directory commands run in and relative paths start from."""
    ssp: Path
    fleet: Path | None = None
    """Services to start per run; None: the SSD's participants are running (or a pool)."""
    stop_time: float | None = None
    args: tuple[str, ...] = ()
    """Extra ``coupler run`` options of every run."""
    timeout: float = 3600.0
    """[s] a run may take, services' start included."""
    health_timeout: float = 60.0
    """[s] a service may take to become healthy."""
    keep_services: bool = False
    """Keep the fleet's services up between runs (a worker's next run takes them): for
    participants that begin afresh at every Initialize, as Coupler's do."""


@dataclass(frozen=True, kw_only=True)
class CampaignSpec:
    """A campaign file."""

    source: Path
    scenario: ScenarioSpec
    out: Path
    variants: Variants
    """Made as they are asked for; at most ``variants.MAXIMUM``. A sequence of variants (a
    slice of another campaign's) is taken as they are."""
    outputs: tuple[Output, ...] = ()
    derive: tuple[Derive, ...] = ()
    """Functions computing more columns from a finished run (:class:`Finished`)."""
    checks: tuple[Check, ...] = ()
    pool: tuple[dict[str, str], ...] = ()
    """Environments naming running participants (``GAIN_PORT``...), one run each at a time."""
    timings: bool = True
    """The table has each run's ``wall_time_s`` and ``realtime_factor``; without them (``[scenario]
    timings = false``) the same campaign run again writes the same campaign.csv."""

    def __post_init__(self) -> None:
        if not isinstance(self.variants, Variants):
            made = Variants([Listed(tuple(dict(v) for v in self.variants))])
            object.__setattr__(self, "variants", made)

    @classmethod
    def load(cls, path: Path, *, root: Path | None = None) -> CampaignSpec:
        """Read a campaign file; relative paths are taken from ``root`` (default: the working
        directory), the [table] file from the campaign file's folder (``spec.read``)."""
        from coupler_orchestrator.tools.campaign.spec import read  # the reader builds these types

        return read(path, root=root)


@dataclass(frozen=True, kw_only=True)
class Finished:
    """What a ``[[derive]]`` function is given: one finished run."""

    directory: Path
    """Its results.csv and summary.json."""
    variant: Mapping[str, Scalar]
    root: Path
    """The campaign's root (the project checkout)."""
    columns: Mapping[str, list[str]]
    """results.csv, column name -> cells (text)."""


@dataclass(frozen=True, kw_only=True)
class RunJob:
    """One run, as sent to a worker (picklable)."""

    index: int
    key: str
    variant: dict[str, Scalar]
    scenario: ScenarioSpec
    outputs: tuple[Output, ...]
    derive: tuple[Derive, ...]
    env: dict[str, str] | None = None
    """A pool entry; None: start the fleet's services on free ports."""
    logs: tuple[str, bool] = ("WARNING", False)
    """The command's log level and whether its lines are JSON: a Dask worker's process logs
    as the command does (its own default would print every INFO line)."""


@dataclass(kw_only=True)
class RunReport:
    """One run's row of the campaign table, and its files (from the worker)."""

    index: int
    key: str
    variant: dict[str, Scalar]
    status: str
    """completed, terminated, failed, aborted, timeout or skipped-from-earlier statuses."""
    reason: str = ""
    wall_time_s: float | None = None
    realtime_factor: float | None = None
    values: dict[str, Scalar | None] = field(default_factory=dict)
    worker: str = ""
    files: dict[str, bytes] = field(default_factory=dict)


@dataclass(frozen=True, kw_only=True)
class CampaignResult:
    """A finished (or interrupted) campaign."""

    reports: tuple[RunReport, ...]
    """One per variant that ran or was skipped, in variant order."""
    table_csv: Path
    table_parquet: Path | None
    skipped: int
    """Runs taken from an earlier campaign run."""

    @property
    def failed(self) -> list[RunReport]:
        return [r for r in self.reports if r.status not in COMPLETED]
