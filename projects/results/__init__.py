"""What processing produced, as the product presents it.

The displacement table (``table``) and the state of every epoch and target (``state``).
"""
