"""Importing in the background (common.imports)."""
from __future__ import annotations

import sys

from common.imports import SWITCH_INTERVAL_S, import_in_background


def test_background_import_loads_in_order_skips_a_missing_module_and_restores_the_switch_interval():
    before = sys.getswitchinterval()
    thread = import_in_background(["json.decoder", "no_such_module_here", "email.parser"])
    assert sys.getswitchinterval() <= SWITCH_INTERVAL_S or not thread.is_alive()
    thread.join(timeout=30)
    assert not thread.is_alive()
    assert "json.decoder" in sys.modules and "email.parser" in sys.modules
    assert sys.getswitchinterval() == before
