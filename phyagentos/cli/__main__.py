"""``python -m phyagentos.cli``: the ``phyagentos`` command."""

import sys

from phyagentos.cli import main

sys.exit(main())
