"""Driver behaviour calibrated from a recording: car following, desired speeds and
lane changes (``twin calibrate``)."""
