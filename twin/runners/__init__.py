"""Runners of many episodes and their folders: ``twin run``, ``twin eval``, ``twin
dataset``, episode sampling and the engines (a process pool or Ray)."""
