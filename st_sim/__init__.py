"""Simulation core: metrics and offline scoring, pymunk crowd simulator (`st_sim.sim`), Rerun logging, plots.

Applications (CLI, evaluators through the envs, demo) live in `st_sim.apps`, above predictor and envs.
"""
