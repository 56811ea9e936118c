"""The traffic manager's rules as compiled kernels over episodes of vehicle slots
(``docs/core.md``): what they work on (:mod:`~twin.traffic.kernels.state`), neighbours
(:mod:`~twin.traffic.kernels.neighbours`), car-following models
(:mod:`~twin.traffic.kernels.models`), car following, emergency braking and cooperation
(:mod:`~twin.traffic.kernels.longitudinal`), lane changes
(:mod:`~twin.traffic.kernels.lane_change`), steering
(:mod:`~twin.traffic.kernels.steering`), the ego controllers
(:mod:`~twin.traffic.kernels.controllers`) and the step that chains them
(:mod:`~twin.traffic.kernels.decide`)."""
