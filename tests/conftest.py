"""Shared fixtures: the AZIMUT-3 geometry and actuator limits, and env factories that close what
they made.

The tests are grouped like the packages: ``tests/estimation``, ``tests/azimut_env``,
``tests/control``, ``tests/train``, ``tests/jobs`` (and ``tests/logs``: robot logs in and out).
Long studies are marked ``slow`` (``pytest -m slow``; the default run leaves them out, see
``pyproject.toml``).
"""

from __future__ import annotations

from collections.abc import Callable, Iterator

import numpy as np
import pytest

from azimut_env.env import AzimutEnv
from azimut_env.vector_env import AzimutVectorEnv
from control.limits import ActuatorLimits
from estimation import RobotGeometry


@pytest.fixture(scope="session")
def geom() -> RobotGeometry:
    """AZIMUT-3's geometry (four wheels, offset b; frozen, so one for the session)."""
    return RobotGeometry.azimut3()


@pytest.fixture(scope="session")
def limits() -> ActuatorLimits:
    """The default actuator limits of the controllers (frozen)."""
    return ActuatorLimits()


def _closing_factory(cls) -> Iterator[Callable]:
    """Yield ``make(**kwargs)`` → a new ``cls(**kwargs)``; close every one made afterwards."""
    made = []

    def make(**kwargs):
        made.append(cls(**kwargs))
        return made[-1]

    yield make
    for env in made:
        env.close()


@pytest.fixture
def make_env() -> Iterator[Callable[..., AzimutEnv]]:
    """``make_env(**kwargs)`` → a fresh :class:`AzimutEnv`; every env made is closed after the test."""
    yield from _closing_factory(AzimutEnv)


@pytest.fixture
def env(make_env) -> AzimutEnv:
    """A fresh default :class:`AzimutEnv` (not reset), closed after the test."""
    return make_env()


@pytest.fixture
def make_vector_env() -> Iterator[Callable[..., AzimutVectorEnv]]:
    """``make_vector_env(**kwargs)`` → a fresh :class:`AzimutVectorEnv`, closed after the test."""
    yield from _closing_factory(AzimutVectorEnv)


@pytest.fixture
def zero_action() -> np.ndarray:
    """The raw action of the default env that commands nothing: (8,) float32 zeros."""
    return np.zeros(8, np.float32)
