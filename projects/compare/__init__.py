"""Whole-scan comparison of two epochs.

Registration, C2C/M3C2 and the span profile (``whole_scan``), and its figure (``figures``).
"""
