"""Stage 6: the frozen plan the master executes — members, links, the execution order computed
once, the time grid and the run's settings. Nothing here knows SSP."""

from __future__ import annotations

from coupler.durations import MAX_LEASE
from coupler.errors import ScenarioError
from coupler_orchestrator.model import Checked, Link, Plan
from coupler_orchestrator.options import RunOptions


def build_plan(checked: Checked, links: tuple[Link, ...], options: RunOptions) -> Plan:
    """The plan of a checked scenario and its links: the members in the order the run's
    semantics step them, and what those semantics add."""
    by_name = {m.name: m for m in checked.members}
    order = checked.semantics.order(checked, links)
    additions = checked.semantics.additions(checked, links)
    return Plan(
        members=checked.members,
        order=tuple(by_name[n] for n in order),
        links=links,
        grid=checked.grid,
        algorithm=checked.algorithm,
        run_id=options.run_id,
        run_secret=options.run_secret,
        lease=lease_of(options, checked),
        realtime_factor=options.realtime_factor or None,
        on_abandoned=options.on_abandoned,
        progress=options.progress,
        native=options.native_steps and additions is None,
        openmcx=additions,
    )


def lease_of(options: RunOptions, checked: Checked) -> float:
    """The lease: given, else the larger of 60 s and four call deadlines, and at least three
    paced steps of the slowest member (so pacing never looks like silence); never above the
    ceiling participants grant (``durations.MAX_LEASE``, 24 h)."""
    if options.lease is not None:
        return options.lease
    lease = min(max(60.0, 4 * options.call_timeout), MAX_LEASE)
    if options.realtime_factor:
        slowest = max((m.multiple for m in checked.members), default=1)
        paced = checked.grid.step * slowest / options.realtime_factor
        if paced > MAX_LEASE / 3:
            raise ScenarioError(
                f"--realtime-factor {options.realtime_factor:g} waits {paced:g} s between two "
                f"steps of a participant, longer than a third of the longest lease ("
                f"{MAX_LEASE:g} s): the participant would end the run; pace faster"
            )
        lease = max(lease, 3 * paced)
    return lease
