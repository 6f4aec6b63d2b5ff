"""Parts shared by the replay and simulated environments: base class, tracks, predictors, metrics, rendering."""
