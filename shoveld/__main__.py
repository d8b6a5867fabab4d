from shoveld.cli import main

raise SystemExit(main())
