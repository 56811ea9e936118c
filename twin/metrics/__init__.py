"""What a finished episode is measured by: fidelity against the recording, energy,
wave dampening, and the table of metrics every runner reads."""
