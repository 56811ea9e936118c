"""Runs for other tools: SUMO (the map's OpenDRIVE is :mod:`mapgen.opendrive`'s, written
with the map)."""
