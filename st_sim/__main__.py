from st_sim.apps.cli import main

raise SystemExit(main())
