"""Ego cameras, labels and dataset writers."""
