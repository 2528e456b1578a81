"""`python -m denali_pipe.cli`: how the workflow's rules run `denali`.

In a local Snakemake run the job goes to the warm-start server when one
answers (`warm_start`), else it runs here."""

import sys

from denali_pipe.cli import main
from denali_pipe.cli.warm_start import hand_off

code = hand_off(sys.argv[1:])
sys.exit(main() if code is None else code)
