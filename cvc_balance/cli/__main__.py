"""``python -m cvc_balance.cli``: the ``cvc-balance`` command."""

import sys

from cvc_balance.cli import main

sys.exit(main())
