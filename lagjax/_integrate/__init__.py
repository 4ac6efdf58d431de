"""The integration loop behind `lagjax.simulate`: plan, step, save, check.

- `simulate`: the entry point; `solver_choice`: which solver runs.
- `step_control`, `time_grid`: fixed step or controller, and the exact grid.
- `fixed_step_loop`, `blocked_loop`, `scan_body`: fixed-step runs as `lax.scan`s.
- `scan_saving`, `off_grid_saves`, `dense_output`: what is saved and where.
- `flat_state`: the state as one vector for diffrax's Runge–Kutta loop.
- `checks`: refusing bad input before tracing, judging a run after its loop.
"""
