"""Examples that use STCrowd from outside its four packages (run them from the repository root)."""
