"""The ``bridgesurvey`` command line."""
