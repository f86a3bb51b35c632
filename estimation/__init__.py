"""estimation: the H representation of planar motion and ICR estimation from steering angles.

Reference: the paper "Estimation of the Instantaneous Centre of Rotation with Nonholonomic
Omnidirectional Mobile Robots" (§2–4). Equation numbers in docstrings refer to it.

Importing the package is light: the names below load with their module on first use
(``from estimation import RobotGeometry`` imports ``estimation.geometry`` only), so that a
package that needs one of them, or only numba's cache folder, does not pay for all of them.
"""

import estimation.numba_cache  # noqa: F401, I001 (first: numba's cache keyed by the sources, before any kernel)
import importlib
import sys
import types

#: the package's names by the module that defines them (loaded on first use: ``__getattr__``)
_EXPORTS = {
    "datasets": ("dataset_d1", "dataset_d2", "dataset_d3"),
    "estimate": ("IT_BEST", "IT_PAPER", "METHODS", "ITDiagnostics", "estimate_eta", "estimate_icr", "estimate_icr_it"),
    "geometry": ("AZIMUT3_ASSUMPTIONS", "RobotGeometry"),
    "hrep": ("canonical_eta", "canonical_lambda", "chart_params", "eta_from_twist", "lambda_distance",
             "lambda_from_chart", "lambda_from_plane", "normalize", "plane_from_lambda", "point_velocity",
             "select_chart", "twist_from_eta"),
    "it": ("ITParams",),
    "kinematics": ("integrate_pose", "mu_from_wheel_speeds", "odometry_twist", "propulsion_circle_normals", "s_perp",
                   "singular_wheels", "steering_chart_jacobian", "steering_from_lambda", "steering_gradient",
                   "steering_path_derivatives", "twist_from_wheels", "wheel_speed_coefficients",
                   "wheel_speed_path_derivative", "wheel_speeds"),
    "oracle": ("OracleParams",),
    "quality": ("QUALITY_F", "quality"),
}
_MODULE_OF = {name: module for module, names in _EXPORTS.items() for name in names}

__all__ = list(_MODULE_OF)


def __getattr__(name: str):
    """A name of :data:`__all__` from its module, or a submodule (``estimation.hrep``), imported
    on first use."""
    if name in _MODULE_OF:
        value = getattr(importlib.import_module(f"{__name__}.{_MODULE_OF[name]}"), name)
        globals()[name] = value
        return value
    if not name.startswith("_"):
        try:
            return importlib.import_module(f"{__name__}.{name}")
        except ModuleNotFoundError as exc:
            if exc.name != f"{__name__}.{name}":
                raise
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))


class _Package(types.ModuleType):
    """The package's module type. The import system binds a submodule to its package's attribute
    of the same name once it loads (``estimation.quality``), which would hide the function
    ``quality`` of :data:`__all__`: a name of ``__all__`` keeps its object."""

    def __setattr__(self, name: str, value) -> None:
        if not (name in _MODULE_OF and isinstance(value, types.ModuleType)):
            super().__setattr__(name, value)


sys.modules[__name__].__class__ = _Package
