"""The batched core: the cosimulation's step (the paper's steps 1 to 8) as compiled
kernels over B episodes of N vehicle slots (``docs/core.md``).

* :mod:`~twin.cosim.core.layout`: the state, struct-of-arrays with a leading episode axis;
* :mod:`~twin.cosim.core.drivers`: drivers and AVs drawn, strategic targets;
* :mod:`~twin.cosim.core.handover`: windows, hand-overs, spawns, the ghost set;
* :mod:`~twin.cosim.core.step`: one step of every episode;
* :mod:`~twin.cosim.core.batch`: the Python side (what a batch shares, a batch).
"""
