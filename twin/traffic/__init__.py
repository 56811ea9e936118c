"""The traffic manager and what it drives with: car-following models, MOBIL, the
lateral and longitudinal controllers, and the ego-controller API with its baselines."""
