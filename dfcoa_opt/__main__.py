"""``python -m dfcoa_opt`` runs the ``dfcoa`` command."""

import sys

from dfcoa_opt.cli import main

sys.exit(main())
