"""i24-twin: a physics-based digital twin of I-24 driven by I-24 MOTION trajectories."""

__version__ = "0.1.0"
