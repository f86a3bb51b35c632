"""azimut_env.physics.engine."""
