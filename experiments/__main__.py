"""`python -m experiments` is the same as the `terrabench` command."""

from .cli import main

raise SystemExit(main())
