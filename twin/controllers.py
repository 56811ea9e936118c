"""The baseline ego controllers under their command-line names,
``--ego-controller twin.controllers:NAME`` (see :mod:`twin.traffic.baselines`)."""

from twin.traffic.baselines import acc, follower_stopper, human, pi_saturation

__all__ = ["acc", "follower_stopper", "human", "pi_saturation"]
