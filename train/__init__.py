"""train: RL baselines (Stable-Baselines3 + PyTorch CPU, the ``rl`` extra).

Not built yet. What exists for it: ``Azimut-v1`` (SB3 ``check_env`` passes), the batched
``azimut_env.vector_env.AzimutVectorEnv`` with its SB3 ``VecEnv`` adapter
(``azimut_env.sb3.AzimutSB3VecEnv``), and the ICR-target and twist action wrappers in
``control.wrappers``.
"""
