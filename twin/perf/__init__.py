"""Performance benchmarks (``twin bench ...``): one JSON line each, medians of
repeats, with the commit and the machine."""
