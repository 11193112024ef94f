"""Systematic errors of a terrestrial scanner, estimated from the campaign's own targets.

A real instrument makes more than random range noise: the air scales its ranges (:mod:`.atmosphere`),
a retro-reflector's strong return biases the range read on it (:mod:`.range_walk`) and the set-up
turns slowly during a long visit (:mod:`.drift`). None of them can be read off one scan, but every
visit re-measures what does not move - the reference targets' mutual geometry and the deck targets'
across-span coordinates - from a new station, at new ranges and incidences, at known times.
:mod:`.adjustment` fits all three terms to that redundancy over the whole campaign at once, and
:mod:`.corrections` applies them to a visit's centroids.
"""
