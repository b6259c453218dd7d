"""``python -m mcl``: the command line."""
from .cli import main

raise SystemExit(main())
