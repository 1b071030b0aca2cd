"""A perception participant: balises found in camera frames, for scoring against ground truth."""
