"""The recording: I-24 MOTION day files ingested into a trajectory store, queries of
it, the embedded synthetic days, Edie speed fields and stop-and-go waves."""
