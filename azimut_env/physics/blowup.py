"""Numerical blow-up: the thresholds past which a robot's state is declared absurd, the codes the
physics summary reports (column :attr:`azimut_env.physics.layout.RS.CODE`) and their messages."""

from __future__ import annotations

from dataclasses import dataclass
from enum import IntEnum

from azimut_env.validation import check_fields, check_positive_fields

__all__ = ["BlowUp", "BlowUpLimits", "BLOWUP_MESSAGES"]


class BlowUp(IntEnum):
    """Blow-up codes, the first check that fails in this order (0: the state is fine)."""

    NONE = 0
    NON_FINITE = 1  #: a non-finite chassis, joint or motor state
    SPEED = 2  #: chassis speed above ``BlowUpLimits.speed``
    YAW_RATE = 3  #: chassis or module angular speed above ``BlowUpLimits.yaw_rate``
    SPIN = 4  #: wheel spin above ``BlowUpLimits.spin``
    POSITION = 5  #: |x| or |y| above ``BlowUpLimits.position``
    ENERGY = 6  #: energy gained step after step beyond the motors' work (:mod:`azimut_env.physics.energy_check`)


BLOWUP_MESSAGES = {
    BlowUp.NON_FINITE: "non-finite physics state",
    BlowUp.SPEED: "body speed exceeds the blow-up limit",
    BlowUp.YAW_RATE: "body angular speed exceeds the blow-up limit",
    BlowUp.SPIN: "wheel spin exceeds the blow-up limit",
    BlowUp.POSITION: "position exceeds the blow-up limit",
    BlowUp.ENERGY: "energy grows beyond the motors' work (a numerical instability: the substep is past its "
                   "stability bound)",
}


@dataclass(frozen=True)
class BlowUpLimits:
    """Thresholds beyond which the state is declared absurd (a numerical blow-up).

    Attributes:
        speed: chassis speed [m/s]. spin: |φ̇| [rad/s]. yaw_rate: chassis or module angular speed
        [rad/s]. position: |x|, |y| [m]. (The steering pivots are joint coordinates since physics
        v2: they cannot tear, so there is no pivot-gap limit.) energy_window: the steps the energy
        check looks back over (an integer ≥ 2); energy_gain: the energy [J] gained over them beyond
        the motors' work (and beyond 1% of the energy), with a gain on 80% of the steps, that
        counts as a blow-up (:mod:`azimut_env.physics.energy_check`).
    """

    speed: float = 20.0
    spin: float = 500.0
    yaw_rate: float = 200.0
    position: float = 1e4
    energy_window: int = 25
    energy_gain: float = 0.25

    def __post_init__(self) -> None:
        check_fields(self)
        # finite: a NaN would disarm the check
        check_positive_fields(self, "speed", "spin", "yaw_rate", "position", "energy_gain")
        if not 2 <= self.energy_window <= 10_000:  # an int already (check_fields)
            raise ValueError(f"BlowUpLimits.energy_window must be in [2, 10000], got {self.energy_window!r}")
