"""The physics world: the only place that creates and moves pybullet bodies."""
