from farsighter.cli import main

raise SystemExit(main())
