"""Campaigns: one scenario run under many variants, in parallel, into one table.

A campaign file (TOML) names the scenario and its variants::

    [scenario]
    fleet = "examples/ramp-gain/fleet.toml"   # services started per run, on free ports
    ssp = "examples/ramp-gain/SystemStructure.ssd"   # default: the fleet file's
    stop_time = 10.0
    out = "results/campaigns/ramp-gain"
    args = ["--step", "0.1"]                  # extra `coupler run` options
    timeout = 600                             # [s] per run
    keep_services = false                     # true: services kept up between runs

    [grid]                                    # every combination (cartesian product)
    "Gain.gain" = [1.0, 2.0, 3.0]
    "Source.slope" = [0.5, 1.0, 2.0]

    [[variant]]                               # and/or explicit variants
    "Gain.gain" = 10.0
    stop_time = 5.0

    [table]                                   # and/or one variant per row of a CSV file
    file = "variants.csv"

    [sample]                                  # and/or n sampled variants, reproducible
    n = 20
    seed = 7
    "Gain.gain" = { uniform = [0.5, 2.0] }
    "Source.slope" = { choice = [1.0, 2.0] }

    [outputs]                                 # campaign table columns from results.csv
    y_max = "max(Gain.y)"                     # max min first last mean count_changes
    y_final = "Gain.y"                        # a bare channel: its last value
    recall = "reports.perception.recall"      # a value of summary.json's reports (an item of
                                              # a list by its index: ...by_distance.3.recall)

    [[derive]]                                # columns computed by a Python function
    function = "coupler_railway.campaign:balise_detections"
    railml = "scenarios/railway/data/annaberg-schwarzenberg.railml"   # its keyword arguments

    [checks]                                  # true/false columns over the outputs
    y_ok = "y_max <= 2 * y_final"

    [pool]                                    # instead of starting services: running ones
    env = [{ GAIN_PORT = "50051" }, { GAIN_PORT = "50052" }]

A campaign has at most 100,000 variants (``variants.MAXIMUM``), counted before any is made.
A variant's keys are ``Component.parameter`` (as ``coupler run --param``; start values too),
``start_time``, ``stop_time`` and ``step``. Each run gets its own participants: the fleet
file's services started on free ports (every ``${NAME_PORT}`` variable of the fleet file gets
one; the SSD reads the same variables), or one entry of the pool, one run per entry at a time.
Each run is a ``coupler run`` process; its files go to ``out/runs/<n>-<key>/`` (results.csv,
summary.json, variant.json, run.log), the key being a hash of the variant and the scenario, so a
campaign run again skips what already completed (``--force`` runs it all again).

Runs execute on this machine (``--jobs N`` at once) or as tasks of a Dask cluster
(``--scheduler tcp://HOST:8786``, or ``local`` for a LocalCluster of worker processes): a task
starts its run's services on its worker, runs it in a scratch folder there and returns the
run's files, so the workers need the project at the same path (a checkout or the image), not a
shared file system.


The package's modules: ``model`` (the types all the others speak), then in the order a campaign
goes: ``spec`` (the file read, refused with the
section and the fix), ``variants`` (the sections that make variants), ``checks`` (the
expressions of [checks]), ``worker`` (one run, as a worker executes it), ``execution`` (every
run, here or on a Dask cluster, skipping what completed before), ``table`` (campaign.csv and
the terminal's table), ``progress`` (what the terminal shows while it runs).
"""

from coupler_orchestrator.tools.campaign.execution import run_campaign
from coupler_orchestrator.tools.campaign.model import (
    CampaignError,
    CampaignResult,
    CampaignSpec,
    Check,
    Derive,
    Finished,
    Output,
    RunJob,
    RunReport,
    Scalar,
    ScenarioSpec,
)
from coupler_orchestrator.tools.campaign.progress import CampaignProgress
from coupler_orchestrator.tools.campaign.table import format_table, table_rows, write_table
from coupler_orchestrator.tools.campaign.variants import variant_key
from coupler_orchestrator.tools.campaign.worker import execute, read_columns, reduce

__all__ = [
    "CampaignError",
    "CampaignProgress",
    "CampaignResult",
    "CampaignSpec",
    "Check",
    "Derive",
    "Finished",
    "Output",
    "RunJob",
    "RunReport",
    "Scalar",
    "ScenarioSpec",
    "execute",
    "format_table",
    "read_columns",
    "reduce",
    "run_campaign",
    "table_rows",
    "variant_key",
    "write_table",
]
