"""Shared basics every layer may use, mapgen included: the I-24 segment's units, road
frame and lanes, the twin's errors, atomic writes, time, paths and the vehicle classes."""
