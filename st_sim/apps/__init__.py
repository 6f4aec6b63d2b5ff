"""Applications on top of the whole stack (replays -> st_sim core -> predictor -> envs -> here).

The CLI, the benchmark evaluators (offline and through the environments), the demo. Nothing below this
package imports it.
"""
