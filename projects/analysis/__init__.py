"""Explaining a displacement history: temperature, construction events with creep, trend and projection."""
