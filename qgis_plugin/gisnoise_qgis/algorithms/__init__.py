"""The provider's algorithms, one module per operation."""

from .contour import NoiseMapAlgorithm
from .design import DesignLayoutAlgorithm
from .diagnose import DiagnoseAlgorithm
from .fit import FitCardAlgorithm

ALGORITHMS = (NoiseMapAlgorithm, FitCardAlgorithm, DiagnoseAlgorithm, DesignLayoutAlgorithm)

__all__ = ["ALGORITHMS", "NoiseMapAlgorithm", "FitCardAlgorithm", "DiagnoseAlgorithm", "DesignLayoutAlgorithm"]
