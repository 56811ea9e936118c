"""``import twin.env`` registers ``i24twin/WaveDampening-v0`` with Gymnasium (the
environment itself is :mod:`twin.control.env`)."""

from twin.control.env import ENV_ID, OBSERVATION, Reward, WaveDampeningEnv, register_envs

__all__ = ["ENV_ID", "OBSERVATION", "Reward", "WaveDampeningEnv", "register_envs"]
