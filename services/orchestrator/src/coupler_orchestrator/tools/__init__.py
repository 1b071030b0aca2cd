"""Commands built on runs: campaigns, fleets of local services, export-fmu and plot."""
