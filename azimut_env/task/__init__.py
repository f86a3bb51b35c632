"""azimut_env.task.core."""
