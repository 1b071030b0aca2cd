"""Stage 8: what a run writes and shows: results.csv, results.parquet, summary.json, the
progress line and the live monitor page. Each output is an ``Observer`` of the run."""
