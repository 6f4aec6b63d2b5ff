from st_sim.cli import main

raise SystemExit(main())
