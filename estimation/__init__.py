"""estimation: the H representation of planar motion and ICR estimation from steering angles.

Reference: the paper "Estimation of the Instantaneous Centre of Rotation with Nonholonomic
Omnidirectional Mobile Robots" (§2–4). Equation numbers in docstrings refer to it.
"""

import estimation.numba_cache  # noqa: F401, I001 (first: numba's cache keyed by the sources, before any kernel)
from estimation.datasets import dataset_d1, dataset_d2, dataset_d3
from estimation.estimate import IT_BEST, IT_PAPER, METHODS, ITDiagnostics, estimate_eta, estimate_icr, estimate_icr_it
from estimation.geometry import AZIMUT3_ASSUMPTIONS, RobotGeometry
from estimation.hrep import (
                   canonical_eta,
                   canonical_lambda,
                   chart_params,
                   eta_from_twist,
                   lambda_distance,
                   lambda_from_chart,
                   lambda_from_plane,
                   normalize,
                   plane_from_lambda,
                   point_velocity,
                   select_chart,
                   twist_from_eta,
)
from estimation.it import ITParams
from estimation.kinematics import (
                   integrate_pose,
                   mu_from_wheel_speeds,
                   odometry_twist,
                   propulsion_circle_normals,
                   s_perp,
                   singular_wheels,
                   steering_chart_jacobian,
                   steering_from_lambda,
                   steering_gradient,
                   steering_path_derivatives,
                   twist_from_wheels,
                   wheel_speed_coefficients,
                   wheel_speed_path_derivative,
                   wheel_speeds,
)
from estimation.oracle import OracleParams
from estimation.quality import QUALITY_F, quality

__all__ = [
    "AZIMUT3_ASSUMPTIONS",
    "IT_BEST",
    "IT_PAPER",
    "ITDiagnostics",
    "ITParams",
    "METHODS",
    "OracleParams",
    "QUALITY_F",
    "dataset_d1",
    "dataset_d2",
    "dataset_d3",
    "estimate_eta",
    "estimate_icr",
    "estimate_icr_it",
    "quality",
    "RobotGeometry",
    "canonical_eta",
    "canonical_lambda",
    "chart_params",
    "eta_from_twist",
    "lambda_distance",
    "lambda_from_chart",
    "lambda_from_plane",
    "integrate_pose",
    "mu_from_wheel_speeds",
    "normalize",
    "odometry_twist",
    "plane_from_lambda",
    "point_velocity",
    "propulsion_circle_normals",
    "s_perp",
    "select_chart",
    "singular_wheels",
    "steering_chart_jacobian",
    "steering_from_lambda",
    "steering_gradient",
    "steering_path_derivatives",
    "twist_from_eta",
    "twist_from_wheels",
    "wheel_speed_coefficients",
    "wheel_speed_path_derivative",
    "wheel_speeds",
]
