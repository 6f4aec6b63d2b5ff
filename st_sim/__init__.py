"""Simulation core: metrics and evaluators, pymunk crowd simulator, Rerun logging and the CLI."""
