from training.translator.schedule import main

raise SystemExit(main())
