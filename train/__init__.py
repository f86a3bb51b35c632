"""train: RL baselines on ``Azimut-v2`` (Stable-Baselines3 + PyTorch CPU, the ``rl`` extra).

* ``azimut train --algo ppo|sac --action raw|residual|icr-rate ...`` (:mod:`jobs.training.command`): N robots in
  one vector env behind the chosen action space (:mod:`train.envs`), VecNormalize saved with the
  model, versioned defaults per algorithm × action space (``train/hyperparams/*.json``), periodic
  evaluation on held-out tracks with the ``azimut eval`` metrics (:mod:`train.callbacks`),
  checkpoints and ``--resume``, TensorBoard logs when ``tensorboard`` is installed;
* :func:`train.policy.load_policy` loads a trained policy with its normalisation, and
  :mod:`train.rollout` runs it on a track with the same log as ``azimut eval`` (which takes
  ``ppo:PATH`` and ``sac:PATH`` controllers).

Importing this package does not import torch or stable-baselines3; its modules that need them
import them when used.
"""

import estimation.numba_cache  # noqa: F401, I001 (first: numba's cache keyed by the sources, before any kernel)
