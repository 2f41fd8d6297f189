from spikeview.cli.main import main

raise SystemExit(main())
