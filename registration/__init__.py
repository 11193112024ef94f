"""Registration of scan epochs and whole-scan change detection."""
import logging

logging.getLogger(__name__).addHandler(logging.NullHandler())
