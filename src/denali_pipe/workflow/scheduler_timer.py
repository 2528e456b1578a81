"""One re-evaluation timer for Snakemake's job scheduler (snakemake 9.27, pinned).

Snakemake's rate limit on starting jobs (`--max-jobs-per-timespan`, on by
default at 100/1s) ends every scheduling pass by starting a
`threading.Timer` that triggers another pass one timespan later
(`JobScheduler._schedule_reevalutation`). A pass that a finished job
triggers thus starts one more chain of timed passes, and the chains add up:
on the demo's rule all (1,225 jobs, 2 cores) the main process held ~400
threads after 530 jobs and spent 55 % of a core scheduling, a quarter of the
machine. A longer timespan thins the chains but delays the exit, which waits
for every pending (non-daemon) timer.

`keep_one_reevaluation_timer` replaces that method with one that starts a
timer only when none is pending, as a daemon thread: the scheduler still
re-checks within one timespan whenever the rate limit held a job back,
and the process exits as soon as the run is done. The Snakefile calls it
when Snakemake loads the workflow.
"""

from __future__ import annotations

import threading

from snakemake.scheduling.job_scheduler import JobScheduler

PATCHED = "_schedule_reevalutation"  # Snakemake's spelling


def _schedule_one_reevaluation(self: JobScheduler, delay: float) -> None:
    pending = getattr(self, "_denali_reevaluation", None)
    if pending is not None and pending.is_alive():
        return
    timer = threading.Timer(delay, self._open_jobs.release)
    timer.daemon = True
    timer.start()
    self._denali_reevaluation = timer


def keep_one_reevaluation_timer() -> None:
    """Patch Snakemake's scheduler (see the module docstring); raises if the
    installed Snakemake no longer has the method, so a version bump cannot
    drop the fix in silence."""
    if not callable(getattr(JobScheduler, PATCHED, None)):
        raise RuntimeError(f"snakemake's JobScheduler has no {PATCHED}: check denali_pipe/workflow/scheduler_timer.py against the installed snakemake")
    setattr(JobScheduler, PATCHED, _schedule_one_reevaluation)
