"""The provider's algorithms, one module per operation."""

from .contour import NoiseMapAlgorithm
from .design import DesignLayoutAlgorithm
from .diagnose import DiagnoseAlgorithm
from .fit import FitCardAlgorithm
from .planning import CompareRoutesAlgorithm, QuieterRouteAlgorithm

ALGORITHMS = (NoiseMapAlgorithm, FitCardAlgorithm, DiagnoseAlgorithm, DesignLayoutAlgorithm, CompareRoutesAlgorithm,
              QuieterRouteAlgorithm)

__all__ = ["ALGORITHMS", "NoiseMapAlgorithm", "FitCardAlgorithm", "DiagnoseAlgorithm", "DesignLayoutAlgorithm",
           "CompareRoutesAlgorithm", "QuieterRouteAlgorithm"]
