"""The campaign store: epochs, imported scans, results, settings and processing."""
import logging

logging.getLogger(__name__).addHandler(logging.NullHandler())
