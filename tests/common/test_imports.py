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


def test_overlapping_background_imports_keep_the_quick_switching_until_the_last_ends(tmp_path, monkeypatch):
    import builtins
    import threading

    gates = {"a": threading.Event(), "b": threading.Event()}
    monkeypatch.setattr(builtins, "_bridgesurvey_test_gates", gates, raising=False)
    for k in gates:  # two modules whose import waits until the test lets it end
        (tmp_path / f"bs_slow_{k}_for_test.py").write_text(
            f"import builtins\nbuiltins._bridgesurvey_test_gates[{k!r}].wait(30)\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    before = sys.getswitchinterval()
    first = import_in_background(["bs_slow_a_for_test"])
    second = import_in_background(["bs_slow_b_for_test"])
    gates["a"].set()
    first.join(timeout=30)
    assert second.is_alive() and sys.getswitchinterval() <= SWITCH_INTERVAL_S  # the second still runs
    gates["b"].set()
    second.join(timeout=30)
    assert not second.is_alive() and sys.getswitchinterval() == before
    for k in gates:
        monkeypatch.delitem(sys.modules, f"bs_slow_{k}_for_test", raising=False)
