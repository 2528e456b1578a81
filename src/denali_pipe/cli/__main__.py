"""`python -m denali_pipe.cli`: how the workflow's rules run `denali`."""

import sys

from denali_pipe.cli import main

sys.exit(main())
