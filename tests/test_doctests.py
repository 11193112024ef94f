"""The examples in the docstrings run and give what they show."""
import doctest
import importlib

import pytest

MODULES = ["common.validation", "common.files", "common.rigid", "projects.store.history", "app.gui.state.plan_edit", "common.flags", "lidar.identification", "lidar.io.names", "lidar.io.intensity",
           "app.gui.state.map_geometry", "projects.results.status"]


@pytest.mark.parametrize("name", MODULES)
def test_docstring_examples(name):
    result = doctest.testmod(importlib.import_module(name), optionflags=doctest.ELLIPSIS)
    assert result.attempted > 0 and result.failed == 0
