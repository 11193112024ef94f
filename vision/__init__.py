"""Dual-camera displacement measurement with camera-motion compensation."""
import logging

logging.getLogger(__name__).addHandler(logging.NullHandler())
