"""Terrestrial LiDAR processing for reflector-based bridge displacement.

Pure computation on numpy arrays and frozen dataclasses: scan I/O, the scan
simulator, reflectance maps, reflector detection and identification, fine-scan
planning, robust target centroids and the reference-group displacement math.
Nothing here touches Qt, a database or global state.
"""
import logging

from common.errors import (
    CancelledError,
    InputError,
    ProcessingError,
    ScanFormatError,
    SurveyError,
)
from lidar.scan import Scan

logging.getLogger(__name__).addHandler(logging.NullHandler())

__all__ = [
    "Scan",
    "SurveyError",
    "ScanFormatError",
    "InputError",
    "ProcessingError",
    "CancelledError",
]
