"""Checks around a run: the inputs before tracing (`inputs`, `initial_state`) and
the finished run after its loop (`run_verdict`)."""
