"""Wave-dampening control on top of the runners: the paired benchmark, the Gymnasium
environment and reinforcement learning."""
