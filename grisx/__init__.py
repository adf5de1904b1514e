"""grisx — resampled importance sampling (RIS, GRIS, ReSTIR) with exact answers.

Layers (imports point one way, top to bottom):

``grisx.theory``   the estimator core (Warp funcs and structs) and toy problems
                   with exact integrals;
``grisx.scene``    scenes and renderers that call the same core;
``grisx.poisson``  screened Poisson reconstruction from gradients;
``grisx.testing``  statistical checks (z-tests, chi-square, Šidák) for users'
                   own estimators.
"""

from grisx.errors import (
    DeviceError,
    GrisxError,
    InvalidParameterError,
    InvalidValueError,
    UnknownNameError,
)

__version__ = "0.1.0"

__all__ = [
    "__version__",
    "GrisxError",
    "UnknownNameError",
    "InvalidParameterError",
    "InvalidValueError",
    "DeviceError",
]
