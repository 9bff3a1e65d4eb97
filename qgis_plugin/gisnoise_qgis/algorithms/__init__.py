"""The provider's algorithms, one module per operation."""

from .contour import NoiseMapAlgorithm
from .diagnose import DiagnoseAlgorithm
from .fit import FitCardAlgorithm

ALGORITHMS = (NoiseMapAlgorithm, FitCardAlgorithm, DiagnoseAlgorithm)

__all__ = ["ALGORITHMS", "NoiseMapAlgorithm", "FitCardAlgorithm", "DiagnoseAlgorithm"]
