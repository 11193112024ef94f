"""The campaign fixtures of tests/projects, for the command-line tests."""
from tests.projects.conftest import field, field_copy, processed, processed_copy  # noqa: F401  (fixtures)
