"""jobs.training."""
