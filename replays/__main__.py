from replays.cli import main

raise SystemExit(main())
