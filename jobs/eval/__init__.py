"""jobs.eval."""
