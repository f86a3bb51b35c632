"""jobs.campaign."""
