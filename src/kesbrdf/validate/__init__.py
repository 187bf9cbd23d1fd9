"""Paper step 4, validate: comparison with measurement, diagnostics, selection, baselines, uncertainty."""
