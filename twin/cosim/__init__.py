"""The paper's cosimulation: its configuration, the ghost-cell loop around the ego, the
behaviours of the visible vehicles, the trajectory log and its pictures."""
