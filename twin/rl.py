"""``twin.rl:policy``, a trained policy as the ego's controller, and ``train_ppo`` (the
``rl`` extra; see :mod:`twin.control.rl`)."""

from twin.control.rl import policy, train_ppo

__all__ = ["policy", "train_ppo"]
