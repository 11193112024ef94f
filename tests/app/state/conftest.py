"""The campaign fixtures of tests/projects."""
from tests.projects.conftest import field, processed, processed_copy  # noqa: F401  (fixtures)
