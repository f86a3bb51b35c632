"""jobs.estimate: ``azimut estimate``, the estimation of a recorded robot log."""
