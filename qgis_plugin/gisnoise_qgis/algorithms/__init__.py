"""The provider's algorithms, one module per operation."""

from .contour import NoiseMapAlgorithm
from .fit import FitCardAlgorithm

ALGORITHMS = (NoiseMapAlgorithm, FitCardAlgorithm)

__all__ = ["ALGORITHMS", "NoiseMapAlgorithm", "FitCardAlgorithm"]
