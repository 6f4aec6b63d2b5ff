from st_sim.apps.cli import main

if __name__ == "__main__":  # guarded: the grid's spawned workers import this module
    raise SystemExit(main())
