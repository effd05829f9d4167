"""``python -m campaign ...``: same as the ``campaign`` console script."""

import sys

from campaign.cli import main

if __name__ == "__main__":
    sys.exit(main())
